"""Tests of the Python module `edrnr` (run by ctest under the python it was
built for, with PYTHONPATH at the build's python/ folder)."""
import math
import os
import tempfile
import unittest

import numpy as np

import edrnr

SOURCE = os.environ.get("EDRNR_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))


class ModuleTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.model = edrnr.make_scene("sphere", res=64, channels=8)
        cls.camera = edrnr.orbit_camera(32)

    def test_simulate_gives_stats_and_an_image(self):
        r = edrnr.simulate(self.model, self.camera)
        img = r["image"]
        self.assertIsInstance(img, np.ndarray)
        self.assertEqual(img.shape, (32, 32, 3))
        self.assertEqual(img.dtype, np.float32)
        s = r["summary"]
        self.assertEqual(s["pixels"], 32 * 32)
        # FPS is the clock over the cycles of the frame.
        self.assertAlmostEqual(s["fps"], s["clock_MHz"] * 1e6 / s["cycles"], delta=1e-6 * s["fps"])
        self.assertEqual(r["stats"]["dram.read_bytes"], s["dram_read_bytes"])
        self.assertGreater(r["energy"]["nJ_per_pixel"], 0)

    def test_the_simulators_image_is_the_chip_engines(self):
        # The cycle simulator's image is bit-identical to the functional chip model's.
        sim = edrnr.simulate(self.model, self.camera)["image"]
        chip = edrnr.render(self.model, self.camera, engine="chip")
        self.assertTrue(np.array_equal(sim, chip))

    def test_every_engine_renders_the_sphere(self):
        ref = edrnr.render(self.model, self.camera, engine="reference", form="float")
        self.assertEqual(set(edrnr.engines()), {"reference", "chip", "fast", "fast-float"})
        for engine in edrnr.engines():
            img = edrnr.render(self.model, self.camera, engine=engine)
            mse = float(np.mean((img - ref) ** 2))
            psnr = 10 * math.log10(1 / mse) if mse > 0 else 99
            self.assertGreater(psnr, 30, engine)
        with self.assertRaises(ValueError):
            edrnr.render(self.model, self.camera, engine="nope")
        # The fast engines end rays at a transmittance of 1e-3 (float path)
        # and 1e-2 (INT8 path) unless told otherwise: every pixel within that
        # of the image with the reference's samples; fast_transmittance_min
        # sets both, fast_int8_transmittance_min the INT8 path's.
        exact = edrnr.render(self.model, self.camera, engine="fast-float", fast_transmittance_min=0)
        early = edrnr.render(self.model, self.camera, engine="fast-float")
        self.assertLessEqual(float(np.max(np.abs(exact - early))), 1e-3 + 1e-6)
        exact8 = edrnr.render(self.model, self.camera, engine="fast", fast_transmittance_min=0)
        early8 = edrnr.render(self.model, self.camera, engine="fast")
        self.assertLessEqual(float(np.max(np.abs(exact8 - early8))), 1e-2 + 1e-6)
        self.assertTrue(np.array_equal(
            exact8, edrnr.render(self.model, self.camera, engine="fast", fast_int8_transmittance_min=0)))
        self.assertFalse(np.array_equal(
            early8, edrnr.render(self.model, self.camera, engine="fast", fast_int8_transmittance_min=1e-3)))
        with self.assertRaises(ValueError):
            edrnr.render(self.model, self.camera, engine="fast", fast_transmittance_min=2)
        with self.assertRaises(ValueError):
            edrnr.render(self.model, self.camera, engine="fast", fast_int8_transmittance_min=-1)

    def test_preset_as_name_dict_and_file_agree(self):
        by_name = edrnr.simulate(self.model, self.camera, preset="edr_nr_40nm")
        as_dict = edrnr.preset("edr_nr_40nm")
        self.assertEqual(as_dict["rp_rob"]["entries"], 16)
        by_dict = edrnr.simulate(self.model, self.camera, preset=as_dict)
        self.assertEqual(by_name["config_hash"], by_dict["config_hash"])
        self.assertEqual(by_name["summary"]["cycles"], by_dict["summary"]["cycles"])
        path = os.path.join(SOURCE, "configs", "chip", "edr_nr_40nm.yaml")
        by_file = edrnr.simulate(self.model, self.camera, preset=path)
        self.assertEqual(by_name["summary"]["cycles"], by_file["summary"]["cycles"])

    def test_overrides_change_the_config(self):
        slow = edrnr.simulate(self.model, self.camera, overrides={"simulator.clock_MHz": 100})
        fast = edrnr.simulate(self.model, self.camera, overrides={"simulator.clock_MHz": 380})
        self.assertEqual(slow["summary"]["clock_MHz"], 100)
        self.assertNotEqual(slow["config_hash"], fast["config_hash"])
        self.assertLess(slow["summary"]["fps"], fast["summary"]["fps"])

    def test_step_returns_metrics_and_errors_as_results(self):
        m = edrnr.step({"rp_rob.entries": 8}, self.model, self.camera)
        self.assertEqual(m["status"], "ok")
        d = edrnr.simulate(self.model, self.camera, overrides={"rp_rob.entries": 8})
        self.assertEqual(m["cycles"], d["summary"]["cycles"])
        self.assertEqual(m["config_hash"], d["config_hash"])
        self.assertAlmostEqual(m["nJ_per_pixel"], d["energy"]["nJ_per_pixel"], places=9)
        self.assertGreater(m["psnr_dB"], 30)
        bad = edrnr.step({"rp_rob.entries": 0}, self.model, self.camera)
        self.assertEqual(bad["status"], "error")
        self.assertIn("entries", bad["error"])
        over = edrnr.step({"feature_cache.bytes": 1048576}, self.model, self.camera)
        self.assertEqual(over["status"], "error")
        self.assertTrue(over["over_budget"])

    def test_bad_input_raises_value_error_naming_it(self):
        with self.assertRaisesRegex(ValueError, "no_such_preset"):
            edrnr.simulate(self.model, self.camera, preset="no_such_preset")
        with self.assertRaisesRegex(ValueError, "entriez"):
            edrnr.simulate(self.model, self.camera, overrides={"rp_rob.entriez": 8})
        with tempfile.TemporaryDirectory() as d:
            bad = os.path.join(d, "bad.edrnr")
            with open(bad, "wb") as f:
                f.write(b"not a model")
            with self.assertRaisesRegex(ValueError, "bad.edrnr"):
                edrnr.load_model(bad)

    def test_bundled_model_loads(self):
        m = edrnr.load_model(os.path.join(SOURCE, "assets", "lego.edrnr"))
        self.assertEqual(m.micro_res, 256)
        self.assertGreater(m.blocks, 0)


if __name__ == "__main__":
    unittest.main()
