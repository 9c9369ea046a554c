"""The hostile-input pass of issue 36, re-runnable: every case of the issue's 18 defects and
their kin, each in a fresh process, classified as clean or a defect.

A case that must be refused is clean when it ends in a one-line error (a ValueError or its kin
from the API; a non-zero exit without a traceback from the CLI) that names what was wrong
(``match``), within its time and memory bounds. A case that must be accepted is clean when it
runs without an error. Time is wall-clock seconds; memory the peak resident set of the case's
process (the CLI's child process for command-line cases), in MB.

Fixtures, made once: a small Katana skill learned from synthetic demonstrations (100 steps),
its demonstrations, the simulated teacher's slot task skill (poses), and the files each case
tampers with.

Run: ``.venv/bin/python benchmarks/hostile_pass.py [--item N] [--list]`` (about 5 minutes);
it prints one row per case and the counts per item.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path

from _common import print_table
from hostile_cases import PY, ROOT, Case, cases, make_fixtures

# -------------------------------------------------------------------------------------- runner
_PY_RUNNER = """
import json, sys, time, traceback
FIX = sys.argv[1]
start = time.perf_counter()
_result = {"error": None}
try:
    import numpy as np
    import pbdkit
    from pbdkit.robots import katana
    exec(compile(sys.stdin.read(), "<case>", "exec"))
except BaseException as exc:
    _result = {"error": type(exc).__name__, "message": str(exc),
           "traceback": traceback.format_exc()[-2000:]}
_result["seconds"] = time.perf_counter() - start
# The peak of this process's own memory (ru_maxrss would count the parent's at the fork).
_result["mb"] = [float(x.split()[1]) / 1024 for x in open("/proc/self/status")
                 if x.startswith("VmHWM:")][0]
print("@@" + json.dumps(_result))
"""

_API_ERRORS = {"ValueError", "TypeError", "FileNotFoundError", "KeyError", "OSError"}


def _cli(args: list[str]) -> list[str]:
    return [PY, "-m", "pbdkit", *args]


def _peak_child_mb(proc_pid: int) -> float:
    try:
        with open(f"/proc/{proc_pid}/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


def run_case(case: Case, fix: Path) -> dict[str, object]:
    env = {**os.environ, "PYTHONWARNINGS": "ignore", "MPLBACKEND": "Agg"}
    if case.kind == "py":
        assert isinstance(case.body, str)
        try:
            done = subprocess.run([PY, "-c", _PY_RUNNER, str(fix)], input=case.body, text=True,
                                  capture_output=True, timeout=case.seconds * 3 + 30, cwd=ROOT,
                                  env=env)  # fmt: skip
        except subprocess.TimeoutExpired:
            return {"ok": False, "why": f"no answer in {case.seconds * 3 + 30:.0f} s"}
        line = [x for x in done.stdout.splitlines() if x.startswith("@@")]
        if not line:
            return {"ok": False, "why": "died: " + done.stderr.strip()[-200:]}
        r = json.loads(line[-1][2:])
        # An API raises: its traceback is the caller's to show; the kind and the message count.
        return _judge(case, r["error"], r.get("message", ""), r["seconds"], r["mb"], "")
    args = [str(a).replace("{FIX}", str(fix)) for a in case.body]
    start = time.perf_counter()
    proc = subprocess.Popen(_cli(args), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, cwd=ROOT, env=env)  # fmt: skip
    mb = 0.0
    text = ""
    if case.kind == "cli":
        deadline = start + case.seconds * 3 + 30
        while proc.poll() is None and time.perf_counter() < deadline:
            mb = max(mb, _peak_child_mb(proc.pid))
            time.sleep(0.05)
        if proc.poll() is None:
            proc.kill()
            return {"ok": False, "why": "no answer in time"}
        text = proc.stdout.read() if proc.stdout else ""
        seconds = time.perf_counter() - start
        error = None if proc.returncode == 0 else f"exit {proc.returncode}"
        return _judge(case, error, text, seconds, mb, text if "Traceback" in text else "")
    # serve / sigint: the view runs until SIGINT; its output read by a thread
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")))  # type: ignore[union-attr]
    reader.start()
    delay = case.extra.get("delay")
    served = False
    while proc.poll() is None and time.perf_counter() - start < case.seconds:
        mb = max(mb, _peak_child_mb(proc.pid))
        if delay is not None and time.perf_counter() - start >= delay:
            break
        if delay is None and any("http://127.0.0.1" in x for x in lines):
            served = True
            break
        time.sleep(0.05)
    after = 0.0
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        signalled = time.perf_counter()
        try:
            proc.wait(timeout=8)
        except subprocess.TimeoutExpired:
            proc.kill()
            return {"ok": False, "why": "SIGINT did not end it in 8 s"}
        after = time.perf_counter() - signalled
    reader.join(timeout=5)
    text = "".join(lines)
    seconds = time.perf_counter() - start
    if case.kind == "sigint":
        ok = "Traceback" not in text or "KeyboardInterrupt" in text.splitlines()[-1:]
        return {
            "ok": ok and after < 5.0,
            "why": f"ended {after:.2f} s after SIGINT",
            "seconds": seconds,
            "mb": mb,
        }
    error = None if served else f"exit {proc.returncode}"
    return _judge(case, error, text, seconds, mb, text if "Traceback" in text else "")


def _judge(case: Case, error: str | None, message: str, seconds: float, mb: float,
           tb: str) -> dict[str, object]:  # fmt: skip
    base = {"seconds": seconds, "mb": mb}
    bounded = seconds <= case.seconds and mb <= case.mb
    limits = f"{seconds:.1f} s, {mb:.0f} MB"
    if error is None:
        ok = case.expect in ("accept", "accept-or-refuse") and bounded
        return {**base, "ok": ok, "why": f"accepted ({limits})"}
    first = (message.strip().splitlines() or [""])[0][:160]
    if case.expect == "accept":
        return {**base, "ok": False, "why": f"refused: {error}: {first}"}
    if tb:
        return {**base, "ok": False, "why": f"traceback: {tb.strip().splitlines()[-1][:160]}"}
    if case.kind == "py" and error not in _API_ERRORS:
        return {**base, "ok": False, "why": f"{error}: {first}"}
    if case.kind == "py" and "\n" in message.strip():
        return {**base, "ok": False, "why": f"a multi-line message: {first}"}
    named = case.match is None or case.match.lower() in message.lower()
    ok = named and bounded
    why = (
        f"refused ({limits}): {first}" if named else f"refused, not naming {case.match!r}: {first}"
    )
    return {**base, "ok": ok, "why": why}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--item", help="only the cases of this item (e.g. 5, or 'kin 5')")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    parser.add_argument("--json", type=Path, help="write the results here too")
    args = parser.parse_args()
    todo = [c for c in cases() if args.item is None or c.item.split()[-1] == args.item]
    if args.list:
        for c in todo:
            print(f"{c.item:6} {c.kind:6} {c.expect:16} {c.name}")
        return
    with tempfile.TemporaryDirectory(prefix="hostile_") as tmp:
        fix = Path(tmp)
        print("making the fixtures ...", flush=True)
        make_fixtures(fix)
        rows, results = [], []
        for c in todo:
            r = run_case(c, fix)
            results.append({"item": c.item, "case": c.name, **r})
            mark = "clean" if r["ok"] else "DEFECT"
            print(f"[{mark:6}] {c.item:6} {c.name}: {r['why']}", flush=True)
            rows.append([c.item, c.name, c.expect, mark, str(r["why"])[:90]])
    print()
    print_table(["item", "case", "expected", "result", "what happened"], rows)
    counts: dict[str, list[int]] = {}
    for c, r in zip(todo, results, strict=True):
        n = counts.setdefault(c.item.split()[-1], [0, 0])
        n[0] += 1
        n[1] += bool(r["ok"])
    print()
    print_table(["item", "cases", "clean", "defects"],
                [[k, str(v[0]), str(v[1]), str(v[0] - v[1])]
                 for k, v in sorted(counts.items(), key=lambda kv: int(kv[0]))])  # fmt: skip
    total, clean = len(results), sum(bool(r["ok"]) for r in results)
    print(f"\n{total} cases: {clean} clean, {total - clean} defects")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
