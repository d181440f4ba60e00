#!/usr/bin/env python3
"""Where a multi-threaded command runs on one core (issue 18's serial fraction, by function).

Records the command with `perf record` (call graphs by DWARF unwinding), cuts the run into windows
of WINDOW seconds and keeps the samples of windows in which one thread alone was sampled: the serial
part of the run. Prints the share of the run that was serial and, per function, the share of the
serial samples whose call stack holds it (inclusive; kernel and loader frames folded away unless
--kernel), so the top of the list names what to parallelise or overlap.

usage: bench/serial_profile.py [--window S] [--top N] [--kernel] [--freq HZ] -- COMMAND [ARGS...]
  e.g. bench/serial_profile.py -- build/apps/ltmapper map integrate --store /tmp/m.ltmap \\
           --aligned OUT/aligned --changes OUT/changes --threads 2
Needs `perf` (Debian: linux-perf) and permission to record (perf_event_paranoid <= 2, or root).
"""
import argparse
import collections
import os
import re
import shutil
import subprocess
import sys
import tempfile

NOISE = re.compile(r"^(\[unknown\]|_start|__libc_start|main$|clone3|start_thread|_dl_|dl_main|"
                   r"entry_SYSCALL|do_syscall|asm_exc|exc_page_fault)")


def samples(script_text):
    """perf script text -> [(tid, time s, [frames, leaf first])]."""
    out, cur = [], None
    for line in script_text.splitlines():
        if not line.strip():
            if cur:
                out.append(cur)
            cur = None
        elif not line[0].isspace():
            m = re.match(r"\s*\S.*?\s+(\d+)\s+([\d.]+):", line)
            cur = (int(m.group(1)), float(m.group(2)), []) if m else None
        elif cur is not None:
            parts = line.strip().split(None, 1)
            if len(parts) == 2:
                frame = re.sub(r"\+0x[0-9a-f]+", "", parts[1]).split(" (")[0]
                cur[2].append((frame[:140], "kernel" in parts[1] or "[k]" in parts[1]))
    if cur:
        out.append(cur)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--window", type=float, default=0.002, help="window length [s] (default 0.002)")
    ap.add_argument("--top", type=int, default=40)
    ap.add_argument("--kernel", action="store_true", help="keep kernel frames")
    ap.add_argument("--freq", type=int, default=4000, help="samples per second per thread")
    ap.add_argument("command", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    cmd = a.command[1:] if a.command[:1] == ["--"] else a.command
    if not cmd:
        ap.error("no command (put it after --)")
    if not shutil.which("perf"):
        sys.exit("serial_profile: perf not found (Debian: apt-get install linux-perf)")
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "perf.data")
        rc = subprocess.call(["perf", "record", "-q", "-F", str(a.freq), "--call-graph", "dwarf,16384",
                              "-o", data, "--"] + cmd, stdout=subprocess.DEVNULL)
        if rc != 0:
            sys.exit("serial_profile: the command (or perf record) exited with %d" % rc)
        text = subprocess.run(["perf", "script", "-i", data], capture_output=True, text=True).stdout
    s = samples(text)
    if not s:
        sys.exit("serial_profile: no samples recorded")
    threads = collections.defaultdict(set)
    for tid, t, _ in s:
        threads[int(t / a.window)].add(tid)
    serial = [x for x in s if len(threads[int(x[1] / a.window)]) == 1]
    span = s[-1][1] - s[0][1]
    single = sum(1 for w in threads.values() if len(w) == 1)
    print("%d samples over %.2f s; %d windows of %.3f s, %d of them with one thread sampled (%.0f %% of "
          "the run); %d serial samples" % (len(s), span, len(threads), a.window, single,
                                           100.0 * single / max(1, len(threads)), len(serial)))
    inclusive = collections.Counter()
    for _, _, frames in serial:
        inclusive.update({f for f, kernel in frames if (a.kernel or not kernel) and not NOISE.match(f)})
    print("% of serial samples | function (inclusive)")
    for f, c in inclusive.most_common(a.top):
        print("%5.1f | %s" % (100.0 * c / len(serial), f))


if __name__ == "__main__":
    main()
