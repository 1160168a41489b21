#!/usr/bin/env python3
"""Every reproducer of the hostile-input issue, with its outcome now: runs
each case in a fresh interpreter under ``ulimit -v 4000000`` (so that an
allocation the core failed to refuse would abort or raise MemoryError) with
a timeout, and prints one line per case: the exception type and the first
words of its message, or how it died.

    PYTHONPATH=python python3 scripts/investigations/hostile_input.py
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

PRELUDE = """
import resource, json, zipfile, hashlib, io, tempfile, os, warnings
resource.setrlimit(resource.RLIMIT_AS, (4_000_000_000, 4_000_000_000))
import numpy as np, sfanav
tmp = tempfile.mkdtemp()
def canonical(o):
    return json.dumps(o, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()
def rewrite(src, dst, fn, compression=zipfile.ZIP_STORED, pad=0):
    with zipfile.ZipFile(src) as zf:
        man = json.loads(zf.read("manifest.json"))
        blobs = {n: zf.read(n) for n in zf.namelist() if n != "manifest.json"}
    man.pop("digest"); fn(man); man["digest"] = hashlib.sha256(canonical(man)).hexdigest()
    text = json.dumps(man); text = text[:-1] + " " * pad + text[-1:]
    with zipfile.ZipFile(dst, "w", compression) as zf:
        zf.writestr("manifest.json", text)
        for n, b in blobs.items(): zf.writestr(n, b)
    return dst
def sfa_file(stats=True):
    p = os.path.join(tmp, "m.sfa")
    sfanav.SFA(2).fit(np.random.default_rng(0).normal(size=(200, 3)).cumsum(0)).save(p, include_statistics=stats)
    return p
"""

CASES = {
    "1 SFA(1, degree=8).fit(rand(20, 100))": "sfanav.SFA(1, degree=8).fit(np.random.rand(20, 100))",
    "1 expand(zeros((10, 1000)), 4)": "sfanav.expand(np.zeros((10, 1000)), 4)",
    "1 Statistics(2**32 + 1)": "sfanav.Statistics(2**32 + 1)",
    "2 Statistics(100000)": "sfanav.Statistics(100000)",
    "3 edited n_features/input_dim = 2**20": """
        def f(m):
            m["state"]["node"]["n_features"] = 2**20; m["state"]["node"]["stages"][0]["input_dim"] = 2**20
        sfanav.load(rewrite(sfa_file(False), os.path.join(tmp, "e.sfa"), f))""",
    "3 edited n_features/input_dim = 1000": """
        def f(m):
            m["state"]["node"]["n_features"] = 1000; m["state"]["node"]["stages"][0]["input_dim"] = 1000
        sfanav.load(rewrite(sfa_file(True), os.path.join(tmp, "e.sfa"), f))""",
    "4 zip bomb (manifest padded with 1 GB of whitespace, deflated)": """
        sfanav.load(rewrite(sfa_file(), os.path.join(tmp, "b.sfa"), lambda m: None, zipfile.ZIP_DEFLATED, 10**9))""",
    "5 weight_sharing=false on a 100000 x 100000 grid": """
        sfanav.Network({"input": {"width": 100000, "height": 100000, "channels": 1},
                        "network": {"weight_sharing": False},
                        "layers": [{"rf": [1, 1], "stride": [1, 1], "out": 1}, {"rf": "full", "out": 1}]})""",
    "6 max_expanded = 10**18 on a 10**6 x 10**6 image": """
        sfanav.Network({"input": {"width": 10**6, "height": 10**6, "channels": 1},
                        "network": {"max_expanded": 10**18}, "layers": [{"rf": "full", "out": 8}]})""",
    "9 expanded_dim(2**64 - 1, 1)": "print(sfanav.expanded_dim(2**64 - 1, 1))",
    "9 weight_sharing = 'false'": """
        sfanav.Network({"input": {"width": 24, "height": 4}, "network": {"weight_sharing": "false"},
                        "layers": [{"rf": "full", "out": 2}]})""",
    "9 unknown section [netwrok]": """
        sfanav.Network({"input": {"width": 24, "height": 4}, "netwrok": {}, "layers": [{"rf": "full", "out": 2}]})""",
    "9 width = 60.9": """
        sfanav.Network({"input": {"width": 60.9, "height": 4}, "layers": [{"rf": "full", "out": 2}]})""",
    "9 model versions 0, -3, true": """
        for v in (0, -3, True):
            try:
                def f(m): m["version"] = v
                sfanav.load(rewrite(sfa_file(), os.path.join(tmp, "v.sfa"), f))
            except ValueError as e:
                print("   ", v, "->", str(e)[-60:])
        raise ValueError("all three refused")""",
    "9 NaN readout array": """
        net = sfanav.Network({"input": {"width": 24, "height": 4},
                              "layers": [{"rf": [6, 4], "stride": [6, 4], "out": 4}, {"rf": "full", "out": 3}]})
        imgs = np.random.default_rng(1).random((30, 4, 24)).cumsum(0)
        net.fit(imgs, sfanav.Rotation(step=6), progress=False)
        p = os.path.join(tmp, "l.sfa")
        sfanav.Localizer(net, n_outputs=3, readout="quadratic").fit(imgs, np.random.rand(30, 2)).save(p)
        with zipfile.ZipFile(p) as zf:
            man = json.loads(zf.read("manifest.json")); blobs = {n: zf.read(n) for n in zf.namelist()}
        name = [n for n in man["arrays"] if "coef" in n][0]
        a = np.load(io.BytesIO(blobs[f"arrays/{name}.npy"])); a.flat[0] = np.nan
        buf = io.BytesIO(); np.save(buf, a); blobs[f"arrays/{name}.npy"] = buf.getvalue()
        man["arrays"][name]["sha256"] = hashlib.sha256(buf.getvalue()).hexdigest()
        man.pop("digest"); man["digest"] = hashlib.sha256(canonical(man)).hexdigest()
        blobs["manifest.json"] = json.dumps(man).encode()
        q = os.path.join(tmp, "n.sfa")
        with zipfile.ZipFile(q, "w") as zf:
            for n, b in blobs.items(): zf.writestr(n, b)
        sfanav.load(q)""",
    "10 batch_size=0": """
        net = sfanav.Network({"input": {"width": 24, "height": 4}, "layers": [{"rf": "full", "out": 2}]})
        net.fit(np.random.rand(10, 4, 24), sfanav.Rotation(step=6), batch_size=0, progress=False)""",
    "10 all-zero weights": "sfanav.Statistics(3).add_samples(np.random.rand(500, 3), np.zeros(500)).covariance()",
    "10 finite input overflowing in the expansion": "sfanav.SFA(2, degree=3).fit(np.random.rand(100, 3) * 1e120)",
    "11 thread counts (max |difference| of outputs, 1 vs 2 threads)": """
        X = np.random.default_rng(0).normal(size=(20000, 30)).cumsum(0)
        out = []
        for t in (1, 2):
            sfanav.set_num_threads(t)
            out.append(sfanav.SFA(3, degree=2, reduce_to=10, precision="mixed").fit(X).transform(X[:100]))
        print("    difference", float(np.abs(out[0] - out[1]).max()))""",
}


def main() -> int:
    for name, body in CASES.items():
        code = PRELUDE + textwrap.dedent(body)
        try:
            r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False)
        except subprocess.TimeoutExpired:
            print(f"{name}: HANG (killed after 120 s)")
            continue
        last = [ln for ln in r.stderr.strip().splitlines() if ln.strip()]
        if r.returncode == 0:
            outcome = "returned normally" + (f" ({r.stdout.strip()})" if r.stdout.strip() else "")
        elif r.returncode < 0:
            outcome = f"DIED by signal {-r.returncode}"
        else:
            outcome = last[-1][:230] if last else f"exit {r.returncode}"
        print(f"{name}: {outcome}")
        extra = [ln for ln in r.stdout.splitlines() if ln.startswith("    ")]
        for ln in extra:
            print(ln)
    return 0


if __name__ == "__main__":
    sys.exit(main())
