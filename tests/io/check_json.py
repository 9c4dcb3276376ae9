"""Parse the JSON files written by the io tests with Python's json module
(strictly: NaN/Infinity are refused) and compare them with the values the
Fortran tests put in.

usage: check_json.py writer <file>
       check_json.py report <file> <nranks>
"""
import json
import math
import sys

failures = []


def check(ok, what):
    if not ok:
        failures.append(what)
        print("FAIL:", what)


def refuse_constant(name):
    raise ValueError(f"non-standard JSON constant {name}")


def load(path):
    with open(path, encoding="utf-8") as f:
        text = f.read()
    check(text.endswith("\n"), "file ends with a newline")
    return json.loads(text, parse_constant=refuse_constant)


def exact(doc, key, value):
    got = doc.get(key, "<missing>")
    same = (got == value and type(got) is type(value)
            and (not isinstance(value, float) or math.copysign(1, got) == math.copysign(1, value)))
    check(same, f"{key}: expected {value!r}, got {got!r}")


def check_writer(path):
    d = load(path)
    exact(d, "name", 'feti "contact" \\ test\nline 2\ttab\x1besc')
    exact(d, "utf8", "\u03bc = 0.3, \u03c3_vm")
    exact(d, "empty_string", "")
    exact(d, "tenth", 0.1)
    exact(d, "third", 1.0 / 3.0)
    exact(d, "negative", -2.5)
    exact(d, "negative_zero", -0.0)
    exact(d, "big", sys.float_info.max)
    exact(d, "small", sys.float_info.min)
    exact(d, "subnormal", 5e-324)
    exact(d, "avogadro", 6.02214076e23)
    check(d.get("nan", 0) is None and "nan" in d, "NaN written as null")
    check(d.get("inf", 0) is None and "inf" in d, "Inf written as null")
    exact(d, "int", -2147483647)
    exact(d, "long", 9007199254740993)
    exact(d, "yes", True)
    exact(d, "no", False)
    check("nothing" in d and d["nothing"] is None, "null member")
    check(d.get("reals") == [1.0, -1e-10, None], f"reals: {d.get('reals')}")
    check(d.get("ints") == [1, 2, 3], "ints")
    check(d.get("no_ints") == [], "empty integer array")
    nested = d.get("nested", {})
    check(nested.get("deeper") == {"level": 3}, "nested object")
    check(nested.get("empty_object") == {}, "empty object")
    check(nested.get("mixed") == [1, 2.5, "three", True, 4, None, [1, []], {"in_array": 1}], "mixed array")
    params = d.get("params", {})
    check(isinstance(params, dict) and "mesh" in params and "solver" in params, "raw params fragment")
    check(d.get("objects") == [{"i": i, "square": float(i * i)} for i in (1, 2, 3)], "array of objects")
    check(list(d)[0] == "name" and list(d)[-1] == "objects", "member order kept")


def check_report(path, nranks):
    d = load(path)
    t = d.get("timings", {})
    check(list(t) == ["assemble", "solve", "output"], f"phases in order: {list(t)}")
    check(t.get("assemble") == {"min": 0.5, "max": 1.5, "mean": 1.0}, "assemble timings")
    check(t.get("solve") == {"min": 2.0, "max": 3.0, "mean": 2.5}, "solve timings")
    check(t.get("output") == {"min": 0.25, "max": 0.75, "mean": 0.5}, "output timings")
    measured = d.get("measured_timings", {})
    check(set(measured) == {"busy", "idle"}, "measured timer names")
    for name, s in measured.items():
        check(0 <= s["min"] <= s["mean"] <= s["max"], f"{name}: min <= mean <= max")
    m = d.get("memory", {}).get("peak_rss_bytes", {})
    check(isinstance(m.get("max"), int) and m["max"] > 64 * 2**20, f"peak rss max > 64 MiB: {m}")
    check(isinstance(m.get("sum"), int) and m["max"] <= m["sum"] <= nranks * m["max"], "max <= sum <= n max")
    check("params" in d and "mesh" in d["params"], "params included")


def main():
    kind, path = sys.argv[1], sys.argv[2]
    try:
        if kind == "writer":
            check_writer(path)
        else:
            check_report(path, int(sys.argv[3]))
    except ValueError as error:
        check(False, f"{path} is not valid JSON: {error}")
    print(f"{path}: {len(failures)} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
