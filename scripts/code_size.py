#!/usr/bin/env python3
"""Source files over 500 lines and functions over 100, in the crates' sources.

    python3 scripts/code_size.py [--files N] [--functions N] [DIR ...]

Prints each file and function past the limits (default 500 and 100 lines; tests count,
blank lines and comments too) and exits 1 if there is any. A parser (`fn parse...`), one
arm per field of a format, may be longer: it is listed as allowed and not counted. Default folders: src,
formats/src, python/src. A function is measured from its `fn` line to the line of its
closing brace, found by counting braces outside comments, strings and character literals.
Standard library only.
"""
import pathlib
import re
import sys


def arg(name, default):
    return int(sys.argv[sys.argv.index(name) + 1]) if name in sys.argv else default


def code_only(line, in_block):
    """`line` without comments, strings and char literals; and whether a block comment
    is still open at its end."""
    out, i = [], 0
    while i < len(line):
        if in_block:
            end = line.find("*/", i)
            if end < 0:
                return "".join(out), True
            i, in_block = end + 2, False
        elif line.startswith("//", i):
            break
        elif line.startswith("/*", i):
            in_block, i = True, i + 2
        elif line[i] == '"':
            j = i + 1
            while j < len(line) and line[j] != '"':
                j += 2 if line[j] == "\\" else 1
            i = j + 1
        elif re.match(r"'(\\.|[^\\'])'", line[i:]):
            i += len(re.match(r"'(\\.|[^\\'])'", line[i:]).group(0))
        else:
            out.append(line[i])
            i += 1
    return "".join(out), in_block


def functions(lines):
    """(name, first line, length) of each function with a body."""
    found, in_block = [], False
    code = []
    for line in lines:
        c, in_block = code_only(line, in_block)
        code.append(c)
    for start, c in enumerate(code):
        m = re.search(r"\bfn\s+(\w+)", c)
        if not m:
            continue
        depth, opened = 0, False
        for end in range(start, len(code)):
            segment = code[end][m.end() :] if end == start else code[end]
            if not opened and ";" in segment.split("{")[0] and "{" not in segment:
                break  # a declaration without a body
            for ch in segment:
                if ch == "{":
                    depth, opened = depth + 1, True
                elif ch == "}":
                    depth -= 1
            if opened and depth == 0:
                found.append((m.group(1), start + 1, end - start + 1))
                break
    return found


def main():
    max_file, max_fn = arg("--files", 500), arg("--functions", 100)
    dirs = [a for a in sys.argv[1:] if not a.startswith("--") and not a.isdigit()]
    dirs = dirs or ["src", "formats/src", "python/src"]
    over = 0
    for d in dirs:
        for path in sorted(pathlib.Path(d).rglob("*.rs")):
            lines = path.read_text(encoding="utf-8").splitlines()
            if len(lines) > max_file:
                print(f"{path}: {len(lines)} lines")
                over += 1
            for name, first, length in functions(lines):
                if length > max_fn and name.startswith("parse"):
                    print(f"{path}:{first}: fn {name}, {length} lines (a parser, allowed)")
                elif length > max_fn:
                    print(f"{path}:{first}: fn {name}, {length} lines")
                    over += 1
    print(f"{over} past {max_file} lines a file or {max_fn} a function")
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main())
