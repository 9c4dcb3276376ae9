#!/usr/bin/env python3
"""Procedure lengths in Fortran sources: every subroutine and function, from its
first line to its `end` line, comments and the procedures it contains
included (a procedure with internal helpers counts them; the helpers are also
measured on their own). Prints the procedures longer
than --max lines (default 120), or --max-app lines (default 80) in a folder
named `app` (src/app: the program's steps read at a glance), and exits 1 if
there is any, 0 otherwise.

    tools/procedure_lengths.py [--max N] [--max-app N] [--list] [paths...]   (default: src)
"""
import argparse
import os
import re
import sys

START = re.compile(r'^\s*(?:(?:pure|elemental|impure|recursive|module|non_recursive)\s+|'
                   r'(?:integer|real|logical|complex|character|type|class)\s*(?:\([^)]*\))?\s+)*'
                   r'(subroutine|function)\s+(\w+)', re.I)
END = re.compile(r'^\s*end\s*(subroutine|function)\b', re.I)
BARE_END = re.compile(r'^\s*end\s*$', re.I)
INTERFACE = re.compile(r'^\s*(abstract\s+)?interface\b', re.I)
END_INTERFACE = re.compile(r'^\s*end\s*interface\b', re.I)


def code(line):
    """The line without its comment (quotes respected) and trailing blanks."""
    quote = None
    for i, c in enumerate(line):
        if quote:
            if c == quote:
                quote = None
        elif c in '\'"':
            quote = c
        elif c == '!':
            return line[:i].rstrip()
    return line.rstrip()


def procedures(path):
    """(name, first line, length) of every procedure of a file."""
    found = []
    stack = []          # [name, first line]
    in_interface = 0
    with open(path, errors='replace') as f:
        lines = f.readlines()
    for number, raw in enumerate(lines, 1):
        line = code(raw)
        if INTERFACE.match(line):
            in_interface += 1
            continue
        if END_INTERFACE.match(line):
            in_interface -= 1
            continue
        if in_interface:
            continue
        if END.match(line) or (BARE_END.match(line) and stack):
            if not stack:
                continue
            name, first = stack.pop()
            found.append((name, first, number - first + 1))
            continue
        m = START.match(line)
        if m and not re.match(r'^\s*end\b', line, re.I) and 'procedure' not in line.lower().split('::')[0]:
            stack.append([m.group(2), number])
    return found


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('paths', nargs='*', default=['src'])
    ap.add_argument('--max', type=int, default=120)
    ap.add_argument('--max-app', type=int, default=80)
    ap.add_argument('--list', action='store_true', help='print every procedure, longest first')
    args = ap.parse_args()
    files = []
    for p in args.paths:
        if os.path.isdir(p):
            for root, _, names in os.walk(p):
                files += [os.path.join(root, n) for n in names if n.endswith(('.f90', '.F90', '.f90.in'))]
        else:
            files.append(p)
    rows = []
    for f in sorted(files):
        rows += [(n, f, first, length) for n, first, length in procedures(f)]
    rows.sort(key=lambda r: -r[3])
    def limit(path):
        return args.max_app if 'app' in os.path.normpath(path).split(os.sep)[:-1] else args.max
    long_ones = [r for r in rows if r[3] > limit(r[1])]
    try:
        for name, f, first, length in (rows if args.list else long_ones):
            print('%5d  %s:%d  %s' % (length, f, first, name))
    except BrokenPipeError:
        return 0
    if not args.list:
        print('%d procedures, %d longer than %d lines (%d in app)' % (len(rows), len(long_ones), args.max,
                                                                       args.max_app))
    return 1 if long_ones else 0


if __name__ == '__main__':
    sys.exit(main())
