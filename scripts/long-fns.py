#!/usr/bin/env python3
"""List Rust functions longer than a limit (default 80 lines), longest first.

Usage: scripts/long-fns.py [--limit N] [DIR_OR_FILE...]
Default directories: host-tools/src control/src xtask/src tests.
A function's length counts from its `fn` line to its closing brace.
"""
import argparse
import pathlib
import re
import signal

FN = re.compile(r"^\s*(?:pub(?:\([^)]*\))?\s+)?(?:const\s+)?(?:async\s+)?(?:unsafe\s+)?"
                r"(?:extern\s+\"[^\"]*\"\s+)?fn\s+([A-Za-z_][A-Za-z0-9_]*)")


def code_only(text):
    """Blank out comments, string and char literals, keeping line breaks."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append("\n" * text.count("\n", i, j))
            i = j
        elif (m := re.match(r'b?r(#*)"', text[i:])) and (i == 0 or not text[i - 1].isalnum()):
            end = '"' + m.group(1)
            j = text.find(end, i + m.end())
            j = n if j < 0 else j + len(end)
            out.append("\n" * text.count("\n", i, j))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append("\n" * text.count("\n", i, j))
            i = j + 1
        elif c == "'" and (m := re.match(r"'(?:\\.[^']*|[^\\'])'", text[i:])):
            i += m.end()
        else:
            out.append(c)
            i += 1
    return "".join(out)


def functions(path):
    lines = code_only(path.read_text()).split("\n")
    for start, line in enumerate(lines):
        m = FN.match(line)
        if not m:
            continue
        depth, opened = 0, False
        for k in range(start, len(lines)):
            for ch in lines[k]:
                if ch == ";" and not opened and depth == 0:
                    break  # a declaration without a body
                if ch == "{":
                    depth, opened = depth + 1, True
                elif ch == "}":
                    depth -= 1
            else:
                if opened and depth == 0:
                    yield m.group(1), start + 1, k - start + 1
                    break
                continue
            break


def main():
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # quiet when piped into head
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limit", type=int, default=80)
    ap.add_argument("dirs", nargs="*",
                    default=["host-tools/src", "control/src", "xtask/src", "tests"])
    args = ap.parse_args()
    found = []
    for d in args.dirs:
        root = pathlib.Path(d)
        paths = [root] if root.is_file() else sorted(root.rglob("*.rs"))
        for path in paths:
            for name, line, length in functions(path):
                if length > args.limit:
                    found.append((length, f"{path}:{line}", name))
    for length, place, name in sorted(found, reverse=True):
        print(f"{length:5}  {place}  {name}")


if __name__ == "__main__":
    main()
