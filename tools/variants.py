"""Solver variants for the judging tools (tools/campaign.py, tests/hard/stability_table.py).

A variant is a name plus namelist settings, by default in &solver:

    --variant NAME                         the program's settings as they are (e.g. 'default')
    --variant NAME:VAR=VALUE[;VAR=VALUE]   &solver VAR = VALUE ...
    --variant NAME:GROUP:VAR=VALUE[;...]   another group
    --variants V1,V2,...                   one variant per value of --variant-variable
                                           (default preconditioner): &solver preconditioner = 'V1', ...

Strings need no quotes (a value that is not a number, a logical or already quoted is
quoted). Each variant's settings are checked once with `feticontact --check` on a merged
input before anything runs (check_variants): a variable the program does not know, or a
value it refuses, ends the tool with the program's message.
Python: /usr/bin/python3 (standard library only).
"""
import os
import re
import subprocess
import tempfile

NAME_RE = re.compile(r"^[A-Za-z0-9_.+-]+$")


def quote_value(value):
    """A namelist value: numbers, logicals, quoted strings and lists as given, other words quoted."""
    v = value.strip()
    if re.match(r"^(['\"]).*\1$", v) or re.match(r"^\.?(true|false|t|f)\.?$", v, re.I):
        return v
    try:
        for part in v.split(","):
            float(part.replace("d", "e").replace("D", "e"))
        return v
    except ValueError:
        return "'%s'" % v


def parse_variant(text):
    """'NAME[:settings]' -> {'name': NAME, 'settings': [(group, var, value), ...]}."""
    name, _, rest = text.partition(":")
    name = name.strip()
    if not NAME_RE.match(name):
        raise ValueError("variant %r: the name must be letters, digits or _.+- (got %r)" % (text, name))
    settings = []
    for item in [s for s in rest.split(";") if s.strip()]:
        lhs, eq, value = item.partition("=")
        if not eq or not value.strip():
            raise ValueError("variant %r: expected VAR=VALUE or GROUP:VAR=VALUE, got %r" % (text, item))
        group, _, var = lhs.strip().rpartition(":")
        group = (group or "solver").strip().lower()
        var = var.strip().lower()
        if not re.match(r"^\w+$", group) or not re.match(r"^\w+(\([^)]*\))?$", var):
            raise ValueError("variant %r: bad variable %r" % (text, lhs))
        settings.append((group, var, quote_value(value)))
    return {"name": name, "settings": settings}


def variants_from_list(text, variable="preconditioner"):
    """'none,lumped' -> [{'name': 'none', settings: [('solver', variable, "'none'")]}, ...]."""
    out = []
    for v in [x.strip() for x in text.split(",") if x.strip()]:
        out.append(parse_variant("%s:%s=%s" % (v, variable, v)))
    return out


def collect(variant_args, variants_arg, variable="preconditioner"):
    """The variants of --variant (repeatable) and --variants, in order; [] when none (no column)."""
    variants = [parse_variant(v) for v in variant_args or []]
    if variants_arg:
        variants += variants_from_list(variants_arg, variable)
    names = [v["name"] for v in variants]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError("variant names must be unique, repeated: %s" % ", ".join(dup))
    return variants


def describe(variant):
    """'&solver preconditioner = 'lumped'' (or 'no settings')."""
    if not variant["settings"]:
        return "no settings"
    return ", ".join("&%s %s = %s" % s for s in variant["settings"])


def merge(groups, variant):
    """The namelist groups (dict group -> [(var, value)]) with the variant's settings."""
    groups = {g: list(items) for g, items in groups.items()}
    for g, v, value in variant["settings"]:
        groups[g] = [kv for kv in groups.get(g, []) if kv[0] != v] + [(v, value)]
    return groups


def check_variants(variants, groups, program, write_namelist, mpiexec=None, mpi_args=()):
    """Run `program --check` on `groups` merged with each variant; raise ValueError with the
    program's message for the first variant it rejects. write_namelist(groups, path) writes
    an input file."""
    env = dict(os.environ)
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    with tempfile.TemporaryDirectory(prefix="fc_variant_") as tmp:
        for variant in variants:
            path = os.path.join(tmp, "%s.nml" % variant["name"])
            merged = merge(groups, variant)
            merged["output"] = [kv for kv in merged.get("output", []) if kv[0] != "directory"] + [
                ("directory", "'%s'" % os.path.join(tmp, "out"))]
            write_namelist(merged, path)
            cmd = ([mpiexec] + list(mpi_args) + ["-n", "1"] if mpiexec else []) + [program, "--check", path]
            try:
                res = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
            except (OSError, subprocess.SubprocessError) as e:
                raise ValueError("variant %r (%s): cannot run %s: %s" % (variant["name"], describe(variant),
                                                                        program, e))
            if res.returncode != 0:
                lines = [l.strip() for l in (res.stdout + res.stderr).splitlines() if l.strip()]
                errors = [l for l in lines if "ERROR" in l or "error" in l.lower()] or lines[-3:]
                raise ValueError("variant %r (%s) is rejected by %s (exit %d): %s" % (
                    variant["name"], describe(variant), program, res.returncode, " / ".join(errors[:3])))
