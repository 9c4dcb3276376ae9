#!/usr/bin/env python3
"""tools/procedure_lengths.py: a procedure of 120 lines passes and one of 121
fails (also an internal one, and a host whose internal procedure makes it
too long), 80 and 81 in a folder `app`, then every procedure of src is at
most 120 lines and every one of src/app at most 80."""
import os
import subprocess
import sys
import tempfile

root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
tool = os.path.join(root, 'tools', 'procedure_lengths.py')


def run(paths):
    return subprocess.run([sys.executable, tool] + paths, capture_output=True, text=True)


def body(n):
    """`n` lines of statements."""
    return ''.join('    x = x + %d\n' % i for i in range(n))


def module(proc):
    return 'module m\n  implicit none\ncontains\n' + proc + 'end module m\n'


def sub(name, n_inner, extra=''):
    """A subroutine of 3 + n_inner lines (+ extra's lines)."""
    return '  subroutine %s(x)\n    integer :: x\n%s%s  end subroutine %s\n' % (name, body(n_inner), extra, name)


cases = [
    ('120 lines', 'case.f90', module(sub('a', 117)), 0),
    ('121 lines', 'case.f90', module(sub('a', 118)), 1),
    ('function of 121 lines', 'case.f90', module('  pure integer(ip) function f(x)\n    integer :: x\n' + body(118)
                                                 + '  end function f\n'), 1),
    ('internal procedures count in the host', 'case.f90', module(sub('a', 70, '  contains\n' + sub('b', 50))), 1),
    ('80 lines in app', os.path.join('app', 'case.f90'), module(sub('a', 77)), 0),
    ('81 lines in app', os.path.join('app', 'case.f90'), module(sub('a', 78)), 1),
]
failed = 0
with tempfile.TemporaryDirectory() as tmp:
    os.makedirs(os.path.join(tmp, 'app'))
    for name, file, text, expected in cases:
        path = os.path.join(tmp, file)
        with open(path, 'w') as f:
            f.write(text)
        rc = run([path]).returncode
        ok = rc == expected
        failed += not ok
        print('%-45s exit %d (expected %d) %s' % (name, rc, expected, 'ok' if ok else 'FAILED'))
r = run([os.path.join(root, 'src')])
print(r.stdout.strip())
failed += r.returncode != 0
sys.exit(1 if failed else 0)
