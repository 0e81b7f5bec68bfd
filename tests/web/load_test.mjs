// Load test and bad-request fuzz of a running `edrnr serve` (loopback only,
// bounded in clients, time and count). Not part of ctest: its figures go into
// docs/web.md.
//
// node tests/web/load_test.mjs --url http://127.0.0.1:PORT/ --pid PID
//      [--clients 20] [--seconds 30] [--model lego] [--width 200] [--fuzz 2000] [--seed 1]
// Exit 1 if any frame request failed or any fuzz request got other than a 4xx.
import { readFileSync } from "node:fs";
import http from "node:http";

const args = Object.fromEntries(
  process.argv.slice(2).reduce((acc, a, i, all) => (a.startsWith("--") ? [...acc, [a.slice(2), all[i + 1]]] : acc), []),
);
const base = new URL(args.url ?? "http://127.0.0.1:8080/");
if (!["127.0.0.1", "localhost", "[::1]"].includes(base.hostname)) throw new Error("loopback addresses only");
const clients = Math.min(64, Number(args.clients ?? 20));
const seconds = Math.min(300, Number(args.seconds ?? 30));
const model = args.model ?? "lego";
const width = Number(args.width ?? 200);
const fuzzCount = Math.min(100000, Number(args.fuzz ?? 2000));
let seed = Number(args.seed ?? 1);

// A small deterministic generator (xorshift32) so a failing case can be replayed.
function rand() {
  seed ^= seed << 13;
  seed >>>= 0;
  seed ^= seed >>> 17;
  seed ^= seed << 5;
  seed >>>= 0;
  return seed / 4294967296;
}
const pick = (a) => a[Math.floor(rand() * a.length)];

function rssKiB(pid) {
  if (!pid) return NaN;
  const m = readFileSync(`/proc/${pid}/status`, "utf8").match(/VmRSS:\s+(\d+)/);
  return m ? Number(m[1]) : NaN;
}

// --- Load: each client asks for one frame after the other, orbiting.
async function loadTest() {
  const deadline = Date.now() + seconds * 1000;
  const rss = [];
  const sampler = setInterval(() => rss.push(rssKiB(args.pid)), 1000);
  const latencies = [];
  let errors = 0;
  let bytes = 0;
  const firstErrors = [];
  await Promise.all(
    Array.from({ length: clients }, async (_, c) => {
      let az = 17 * c;
      while (Date.now() < deadline) {
        az += 7;
        const t0 = performance.now();
        try {
          const res = await fetch(new URL(`/api/render?model=${model}&w=${width}&az=${az}&el=25`, base));
          const body = await res.arrayBuffer();
          if (res.status !== 200 || body.byteLength !== width * width * 4) {
            errors++;
            if (firstErrors.length < 5) firstErrors.push(`${res.status} ${new TextDecoder().decode(body).slice(0, 200)}`);
          } else {
            bytes += body.byteLength;
            latencies.push(performance.now() - t0);
          }
        } catch (e) {
          errors++;
          if (firstErrors.length < 5) firstErrors.push(String(e));
        }
      }
    }),
  );
  clearInterval(sampler);
  latencies.sort((a, b) => a - b);
  const q = (p) => latencies[Math.min(latencies.length - 1, Math.floor(p * latencies.length))] ?? NaN;
  return {
    clients,
    seconds,
    frames: latencies.length,
    frames_per_second: latencies.length / seconds,
    errors,
    first_errors: firstErrors,
    MB_delivered: bytes / 1e6,
    latency_ms: { p50: q(0.5), p95: q(0.95), max: q(1) },
    rss_MiB: rss.filter(Number.isFinite).map((k) => Math.round(k / 102.4) / 10),
  };
}

// --- Fuzz: every request carries at least one invalid part by construction.
const badNumbers = ["nan", "inf", "-1e309", "1e400", "", "abc", "0x10", "1,5", "99999999999999999999", "1e6", "%00", "400.5x"];
const badNames = ["..", "../lego", "..%2Flego", "%2Fetc%2Fpasswd", ".hidden", "a%2Fb", "x".repeat(300), "nothere", "lego%00", "%C3%28", "le%20go"];
function fuzzRequest() {
  const kind = Math.floor(rand() * 9);
  const num = () => pick(badNumbers);
  switch (kind) {
    case 0:
      return { path: `/api/render?model=${pick(badNames)}&w=200` };
    case 1:
      return { path: `/api/render?model=${model}&${pick(["w", "h", "az", "el", "radius", "fov", "view"])}=${num()}` };
    case 2:
      return { path: `/api/render?model=${model}&${pick(["zz", "format", "dataset"])}=${pick(badNames)}` };
    case 3:
      return { path: `/api/groundtruth?dataset=${pick(badNames)}&view=${Math.floor(rand() * 10)}` };
    case 4:
      return { path: `/api/groundtruth?dataset=${model}&view=${pick(["-1", "25", "1e9", "x", ""])}` };
    case 5:
      return { path: `/api/sim/${pick(["x", "-1", "1.5", "99999999999999999999999", "%2e%2e", "0x1", "123456789"])}${pick(["", "/image/0", "/trace/0", "/image/x", "/trace/99"])}` };
    case 6: {
      const bodies = [
        "not json",
        "[]",
        "null",
        '{"model":"lego"}',
        `{"client":"fuzz-client-${Math.floor(rand() * 1e6)}","model":"${pick(badNames)}"}`,
        `{"client":"fuzz-client-1","model":"${model}","w":${pick(["1e9", "-1", "0", "5000"])}}`,
        `{"client":"fuzz-client-1","model":"${model}","preset":"${pick(badNames)}"}`,
        `{"client":"x","model":"${model}"}`,
        `{"client":"fuzz-client-1","model":"${model}","nested":{"a":1}}`,
        '{"a":"' + "x".repeat(5000) + '"}',
      ];
      return { path: "/api/sim", method: "POST", body: pick(bodies) };
    }
    case 7:
      return { path: `/api/sim/${Math.floor(rand() * 1000)}?client=${pick(["", "short", "x".repeat(100), "bad/id!"])}`, method: "DELETE" };
    default: {
      // Random paths and methods.
      const seg = () => pick(["api", "render", "sim", "..", "%2e%2e", "catalog", "x".repeat(1 + Math.floor(rand() * 50)), "index.html%00", "etc", "passwd"]);
      const path = "/" + Array.from({ length: 1 + Math.floor(rand() * 4) }, seg).join("/") + pick(["?x=1", "?model=..", "?w=" + "9".repeat(200)]);
      const method = pick(["PUT", "PATCH", "DELETE", "POST", "GET"]);
      return { path, method, body: method === "GET" ? undefined : "x" };
    }
  }
}

// The path goes out exactly as written (fetch would resolve "/a/%2e%2e" to "/").
function rawRequest(method, path, body) {
  return new Promise((resolve, reject) => {
    const req = http.request(
      { host: base.hostname, port: base.port, method, path, headers: body ? { "Content-Type": "application/json" } : {} },
      (res) => {
        let text = "";
        res.setEncoding("utf8");
        res.on("data", (d) => (text += d));
        res.on("end", () => resolve({ status: res.statusCode, text }));
      },
    );
    req.on("error", reject);
    req.end(body);
  });
}

async function fuzz() {
  const byStatus = {};
  const failures = [];
  for (let i = 0; i < fuzzCount; i++) {
    const r = fuzzRequest();
    let status = 0;
    try {
      const res = await rawRequest(r.method ?? "GET", r.path, r.body);
      status = res.status;
      if (status >= 400 && status < 500 && !res.text.startsWith("{")) status = -status; // not a JSON error
    } catch (e) {
      status = 0;
    }
    byStatus[status] = (byStatus[status] ?? 0) + 1;
    const ok = status >= 400 && status < 500;
    if (!ok && failures.length < 10) failures.push(`${r.method ?? "GET"} ${r.path.slice(0, 120)} -> ${status}`);
  }
  return { requests: fuzzCount, by_status: byStatus, failures };
}

const rssBefore = rssKiB(args.pid);
const load = await loadTest();
const fz = await fuzz();
const health = await fetch(new URL("/api/health", base)).then((r) => r.status).catch(() => 0);
const result = { rss_before_MiB: Math.round(rssBefore / 102.4) / 10, load, fuzz: fz, healthy_after: health === 200, rss_after_MiB: Math.round(rssKiB(args.pid) / 102.4) / 10 };
console.log(JSON.stringify(result, null, 1));
process.exit(load.errors === 0 && fz.failures.length === 0 && health === 200 ? 0 : 1);
