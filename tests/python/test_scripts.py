"""The Python scripts that come with the sweeps: examples/random_search.py and
scripts/pareto.py, run on small inputs (skipped without matplotlib)."""
import csv
import json
import os
import subprocess
import sys
import tempfile
import unittest

SOURCE = os.environ.get("EDRNR_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))

try:
    import matplotlib  # noqa: F401

    HAVE_MATPLOTLIB = True
except ImportError:
    HAVE_MATPLOTLIB = False


@unittest.skipUnless(HAVE_MATPLOTLIB, "matplotlib is not installed")
class ScriptsTest(unittest.TestCase):
    def test_random_search_writes_a_front_with_the_paper_design(self):
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "search")
            subprocess.run([sys.executable, os.path.join(SOURCE, "examples", "random_search.py"), "--samples", "3",
                            "--width", "24", "--out", out], check=True, capture_output=True, env=os.environ)
            with open(os.path.join(out, "front.csv"), encoding="utf-8") as f:
                rows = list(csv.DictReader(f))
            self.assertGreaterEqual(len(rows), 1)
            fps = [float(r["fps"]) for r in rows]
            self.assertEqual(fps, sorted(fps, reverse=True))
            self.assertGreater(os.path.getsize(os.path.join(out, "front.png")), 1000)

    def test_pareto_plot_of_a_sweep_folder(self):
        with tempfile.TemporaryDirectory() as d:
            rows = [
                {"point": 0, "status": "ok", "metrics": {"fps": 10.0, "nJ_per_pixel": 5.0, "sram_total_bytes": 100}},
                {"point": 1, "status": "ok", "metrics": {"fps": 8.0, "nJ_per_pixel": 6.0, "sram_total_bytes": 100}},
                {"point": 2, "status": "error", "metrics": {"fps": None, "nJ_per_pixel": None, "sram_total_bytes": 50}},
            ]
            with open(os.path.join(d, "results.jsonl"), "w", encoding="utf-8") as f:
                f.write("".join(json.dumps(r) + "\n" for r in rows))
            with open(os.path.join(d, "pareto.csv"), "w", encoding="utf-8") as f:
                f.write("point,config_hash,fps,nJ_per_pixel,sram_total_bytes,on_front,design\n")
                f.write("0,abc,10.0,5.0,100,1,base\n")
            r = subprocess.run([sys.executable, os.path.join(SOURCE, "scripts", "pareto.py"), d], capture_output=True)
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertGreater(os.path.getsize(os.path.join(d, "pareto.png")), 1000)
            # A folder without results is refused with a message and status 2.
            empty = os.path.join(d, "empty")
            os.mkdir(empty)
            r = subprocess.run([sys.executable, os.path.join(SOURCE, "scripts", "pareto.py"), empty],
                               capture_output=True, text=True)
            self.assertEqual(r.returncode, 2)
            self.assertIn("cannot read", r.stderr)


if __name__ == "__main__":
    unittest.main()
