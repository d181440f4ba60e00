"""Shared by the bench matrices: one command run under /usr/bin/time with its output in a log."""
import subprocess
import time


def timed(cmd, log):
    """Runs `cmd` with stdout and stderr in `log`; returns (user + sys CPU s, peak RSS MB, wall s).
    Raises RuntimeError with the log's tail when the command fails."""
    t0 = time.time()
    with open(log, "w") as out:
        rc = subprocess.call(["/usr/bin/time", "-f", "%U %S %M", "-o", log + ".time"] + cmd, stdout=out,
                             stderr=subprocess.STDOUT)
    wall = time.time() - t0
    if rc != 0:
        raise RuntimeError("failed (%d): %s\n%s" % (rc, " ".join(cmd), open(log).read()[-2000:]))
    user, sys_, rss = open(log + ".time").read().split()[-3:]
    return float(user) + float(sys_), int(rss) / 1024.0, wall
