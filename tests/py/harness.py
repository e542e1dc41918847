# tests/py/harness.py: what the python tests share: the repository and build paths, the built
# programs first on PATH, a scratch folder per test, check() that records failures, run() that
# stops the test when a program it relies on fails, and finish() for the exit status.
import os
import subprocess
import sys

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
os.environ["PATH"] = os.path.join(ROOT, BUILD, "bin") + os.pathsep + os.environ["PATH"]
failures = []


def tmpdir(name):
    """The test's scratch folder, build/test-tmp/NAME (made if missing)."""
    path = os.path.join(ROOT, BUILD, "test-tmp", name)
    os.makedirs(path, exist_ok=True)
    return path


def check(cond, msg):
    print(("ok    " if cond else "FAIL  ") + msg)
    if not cond:
        failures.append(msg)


def runner(cwd):
    """run(*cmd) in cwd: the completed process; a nonzero exit ends the test with its output."""
    def run(*cmd):
        r = subprocess.run(list(cmd), cwd=cwd, capture_output=True, text=True)
        if r.returncode != 0:
            print(r.stdout, r.stderr)
            raise SystemExit("command failed (%d): %s" % (r.returncode, " ".join(cmd)))
        return r
    return run


def finish():
    """Exit 1 with the count when a check failed."""
    if failures:
        print("%d failure(s)" % len(failures))
        sys.exit(1)
