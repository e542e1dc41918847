#!/usr/bin/python3
# tests/py/test_doc_citations.py: the repository stands alone. Every document the code, tests
# and docs cite must be in the repository, and every cited section of it must exist:
#   docs/THEORY.md section 8, docs/THEORY.md sections 2 and 3  -> a heading "## 8." (and "## 2.", "## 3.")
#   docs/TOOLCHAIN.md section 3g                                -> "### g." under "## 3."
#   docs/TOOLCHAIN.md gotcha 11, gotchas 8-10                   -> items 11, 8..10 of its "Gotchas"
#   any other upper-case name ending in .md                       -> a tracked file of that name
# and nothing may refer to the developers' private briefing folder (SHARED below), which users
# of the repository do not have.
# SPDX-License-Identifier: MIT
import os
import re
import subprocess
import sys

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "../..")))
SELF = "tests/py/test_doc_citations.py"
SHARED = ".." + "/shared"  # spelled apart so that this file does not cite it itself


def tracked_files():
    try:
        out = subprocess.run(["git", "-C", ROOT, "ls-files"], capture_output=True, text=True,
                             check=True).stdout.split("\n")
        files = [f for f in out if f]
        if files:
            return files
    except (OSError, subprocess.CalledProcessError):
        pass
    files = []
    for d, dirs, names in os.walk(ROOT):
        dirs[:] = [x for x in dirs if not x.startswith(".") and not x.startswith("build")]
        files += [os.path.relpath(os.path.join(d, n), ROOT) for n in names]
    return files


def sections(text):
    """Section keys of a document: '8' for '## 8. ...', '3g' for '### g. ...' under '## 3.',
    'gotcha 11' for item '11.' of a section whose heading contains 'Gotchas'."""
    keys, major, gotchas = set(), None, False
    for line in text.split("\n"):
        m = re.match(r"^## (\d+)\.\s", line)
        if m:
            major, gotchas = m.group(1), "otcha" in line
            keys.add(major)
            continue
        m = re.match(r"^### ([a-z])\.\s", line)
        if m and major:
            keys.add(major + m.group(1))
            continue
        m = re.match(r"^(\d+)\. ", line)
        if m and gotchas:
            keys.add("gotcha " + m.group(1))
    return keys


CITE = re.compile(r"(?<![\w/.-])((?:docs/)?([A-Z][A-Z_]+)\.md)"
                  r"(?:\s+(sections?|gotchas?)\s+(\d+[a-z]?)(?:(?:\s+and\s+|\s*-\s*|,\s*)(\d+[a-z]?))?)?")


def check_text(name, text, docs, names, problems):
    """Append to problems every bad citation in text (name: where it comes from)."""
    for ln, line in enumerate(text.split("\n"), 1):
        if SHARED in line:
            problems.append("%s:%d: refers to %s/, which users do not have" % (name, ln, SHARED))
        for m in CITE.finditer(line):
            path, base, kind, a, b = m.groups()
            fname = base + ".md"
            target = path if path.startswith("docs/") else None
            if target is None:
                if fname not in names:
                    problems.append("%s:%d: cites %s, which is not in the repository" % (name, ln, fname))
                continue
            if target not in docs:
                problems.append("%s:%d: cites %s, which is not in the repository" % (name, ln, target))
                continue
            if not kind:
                continue
            wanted = [a]
            if b:
                if kind.startswith("gotcha") and "-" in m.group(0) and a.isdigit() and b.isdigit():
                    wanted = [str(i) for i in range(int(a), int(b) + 1)]
                else:
                    wanted.append(b)
            for w in wanted:
                key = ("gotcha " + w) if kind.startswith("gotcha") else w
                if key not in docs[target]:
                    problems.append("%s:%d: cites %s %s %s, which has no such section" %
                                    (name, ln, target, kind, w))


def main():
    files = tracked_files()
    names = {os.path.basename(f) for f in files}
    docs = {}
    for f in files:
        if f.endswith(".md") and os.path.isfile(os.path.join(ROOT, f)):
            with open(os.path.join(ROOT, f), encoding="utf-8", errors="replace") as fp:
                docs[f] = sections(fp.read())
    # --- self-check: the scanner must catch each kind of bad citation --------------------------
    missing = "docs/NOPE" + ".md"  # a document that does not exist (spelled apart, as above)
    synthetic = ("see docs/THEORY.md section 99\n" + "BRIEF" + ".md /ffrf\n"
                 "in " + SHARED + "/THEORY.md\n" + missing + "\n"
                 "docs/TOOLCHAIN.md gotchas 1-999\ndocs/THEORY.md section 1\n")
    caught = []
    check_text("synthetic", synthetic, docs, names, caught)
    lines = sorted({int(p.split(":")[1]) for p in caught})
    ok_self = lines == [1, 2, 3, 4, 5]
    print(("ok    " if ok_self else "FAIL  ") + "scanner catches a made-up section, document, "
          "the private briefing folder and a gotcha range, and passes a good citation (lines %s)" % lines)
    # --- the repository ------------------------------------------------------------------------
    problems = []
    n = 0
    for f in files:
        if f == SELF or f.endswith((".svg", ".png", ".h5", ".msh", ".stl", ".off", ".step")):
            continue
        p = os.path.join(ROOT, f)
        if not os.path.isfile(p):
            continue
        with open(p, encoding="utf-8", errors="replace") as fp:
            text = fp.read()
        n += 1
        check_text(f, text, docs, names, problems)
    for p in problems:
        print("FAIL  " + p)
    print("%d files scanned, %d bad citations" % (n, len(problems)))
    return 0 if ok_self and not problems else 1


if __name__ == "__main__":
    sys.exit(main())
