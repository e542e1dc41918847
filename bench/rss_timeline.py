#!/usr/bin/python3
# bench/rss_timeline.py: where a program's memory goes. Runs COMMAND, samples its resident set
# (/proc/PID/status VmRSS) every 0.1 s and time-stamps its standard-error lines; prints one
# timeline (seconds since start): a line for every RSS change above 50 MB and every log line,
# then the sampled peak. Use with -v so the program's stage lines mark the timeline.
# Usage: /usr/bin/python3 bench/rss_timeline.py COMMAND [ARGS...]  (e.g. gmsolve S.yaml -v)
import subprocess
import sys
import threading
import time

if len(sys.argv) < 2:
    sys.exit("usage: rss_timeline.py COMMAND [ARGS...]")
t0 = time.time()
p = subprocess.Popen(sys.argv[1:], stderr=subprocess.PIPE, text=True)
events = []


def read_log():
    for line in p.stderr:
        events.append((time.time() - t0, "LOG " + line.rstrip()[:160]))


reader = threading.Thread(target=read_log)
reader.start()
peak = last = 0
while p.poll() is None:
    try:
        with open("/proc/%d/status" % p.pid) as f:
            for line in f:
                if line.startswith("VmRSS"):
                    r = int(line.split()[1]) // 1024
                    peak = max(peak, r)
                    if abs(r - last) > 50:
                        events.append((time.time() - t0, "RSS %d MB" % r))
                        last = r
    except OSError:  # the process ended between poll and open
        pass
    time.sleep(0.1)
reader.join()
for t, e in sorted(events):
    print("%8.2f %s" % (t, e))
print("peak sampled %d MB; exit %d" % (peak, p.returncode))
sys.exit(p.returncode)
