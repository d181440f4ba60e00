"""Shared by the bench matrices: one command run with its output in a log, its CPU time and peak RSS
read from the kernel's accounting of the child (wait4), so no /usr/bin/time is needed."""
import os
import subprocess
import time


def timed(cmd, log):
    """Runs `cmd` with stdout and stderr in `log`; returns (user + sys CPU s, peak RSS MB, wall s).
    Raises RuntimeError with the log's tail when the command fails."""
    t0 = time.time()
    with open(log, "w") as out:
        child = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = rc = os.waitstatus_to_exitcode(status)
    wall = time.time() - t0
    if rc != 0:
        raise RuntimeError("failed (%d): %s\n%s" % (rc, " ".join(cmd), open(log).read()[-2000:]))
    return usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0, wall
