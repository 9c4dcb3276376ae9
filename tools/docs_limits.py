#!/usr/bin/env python3
"""The size limits of the documentation: no table cell over --max-cell
characters (default 600) in docs/*.md, tests/README.md and README.md, and
docs/RESULTS.md at most --max-results lines (default 1000; the history of
its tables lives in git). Prints each violation (file:line, what) and exits
1 if there is any, 0 otherwise.

    tools/docs_limits.py [--max-cell N] [--max-results N] [--root DIR]
"""
import argparse
import glob
import os
import sys


def cells(line):
    """The cells of a markdown table row ('|' escaped as '\\|' stays in its cell)."""
    body = line.strip()
    if body.startswith('|'):
        body = body[1:]
    if body.endswith('|') and not body.endswith('\\|'):
        body = body[:-1]
    out, cur, i = [], '', 0
    while i < len(body):
        if body[i] == '\\' and i + 1 < len(body) and body[i + 1] == '|':
            cur += '\\|'
            i += 2
            continue
        if body[i] == '|':
            out.append(cur)
            cur = ''
        else:
            cur += body[i]
        i += 1
    out.append(cur)
    return [c.strip() for c in out]


def check(root, max_cell, max_results):
    problems = []
    files = sorted(glob.glob(os.path.join(root, 'docs', '*.md')))
    files += [p for p in (os.path.join(root, 'tests', 'README.md'), os.path.join(root, 'README.md'))
              if os.path.exists(p)]
    for path in files:
        rel = os.path.relpath(path, root)
        fence = False
        with open(path, errors='replace') as f:
            lines = f.read().split('\n')
        for number, line in enumerate(lines, 1):
            if line.lstrip().startswith('```'):
                fence = not fence
            if fence or not line.lstrip().startswith('|'):
                continue
            for k, cell in enumerate(cells(line), 1):
                if len(cell) > max_cell:
                    problems.append('%s:%d: table cell %d has %d characters (at most %d)'
                                    % (rel, number, k, len(cell), max_cell))
        if rel == os.path.join('docs', 'RESULTS.md'):
            n = len(lines) - (1 if lines and lines[-1] == '' else 0)
            if n > max_results:
                problems.append('%s: %d lines (at most %d; older tables go to git)' % (rel, n, max_results))
    return problems


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--max-cell', type=int, default=600)
    parser.add_argument('--max-results', type=int, default=1000)
    parser.add_argument('--root', default=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    args = parser.parse_args()
    problems = check(args.root, args.max_cell, args.max_results)
    for p in problems:
        print(p)
    print('%d problem(s)' % len(problems))
    return 1 if problems else 0


if __name__ == '__main__':
    sys.exit(main())
