#!/usr/bin/env python3
"""Checks api/openapi.yaml's per-kind params schemas field by field against
the params specs the daemon reads with (src/jobs/spec.h), as printed by the
params_spec tool: the same field names, types, defaults, minimum/maximum,
enums, array sizes and nested fields. Usage:

  params_spec_check.py SPEC.yaml PARAMS_SPEC_EXE
"""
import json
import math
import subprocess
import sys

import yaml

# The params schema of each kind (x-kinds in the spec names them too).
SCHEMAS = {
    "preview": "PreviewParams",
    "voxelize": "VoxelizeParams",
    "render": "RenderParams",
    "gregory": "GregoryParams",
    "catmull-clark": "CatmullClarkParams",
}


class Checker:
    def __init__(self, api):
        self.api = api
        self.errors = []

    def deref(self, s):
        while isinstance(s, dict) and "$ref" in s:
            ref = s["$ref"]
            assert ref.startswith("#/"), ref
            node = self.api
            for part in ref[2:].split("/"):
                node = node[part]
            rest = {k: v for k, v in s.items() if k != "$ref"}
            s = {**node, **rest}
        return s

    def resolve(self, s):
        """The schema with $ref, allOf and a null branch of anyOf/oneOf
        folded in; returns (schema, nullable)."""
        s = self.deref(s)
        nullable = False
        for key in ("anyOf", "oneOf"):
            if key in s:
                branches = [self.deref(b) for b in s[key]]
                rest = [b for b in branches if b.get("type") != "null"]
                nullable = len(rest) < len(branches)
                if len(rest) == 1:
                    s = {**{k: v for k, v in s.items() if k != key}, **rest[0]}
                    s, n2 = self.resolve(s)
                    nullable = nullable or n2
        if "allOf" in s:
            merged = {k: v for k, v in s.items() if k != "allOf"}
            for b in s["allOf"]:
                b, _ = self.resolve(b)
                merged = {**b, **merged}
            s = merged
        t = s.get("type")
        if isinstance(t, list) and "null" in t:
            nullable = True
            rest = [x for x in t if x != "null"]
            s = {**s, "type": rest[0] if len(rest) == 1 else rest}
        return s, nullable

    def err(self, path, msg):
        self.errors.append("%s: %s" % (path, msg))

    @staticmethod
    def same(a, b):
        if isinstance(a, (int, float)) and isinstance(b, (int, float)) and \
                not isinstance(a, bool) and not isinstance(b, bool):
            return math.isclose(a, b, rel_tol=1e-12, abs_tol=0)
        if isinstance(a, list) and isinstance(b, list):
            return len(a) == len(b) and all(Checker.same(x, y) for x, y in zip(a, b))
        return a == b

    def field(self, path, spec, schema):
        s, nullable = self.resolve(schema)
        if spec["type"] == "custom":
            return  # read by the kind itself; only its name is checked
        if s.get("type") != spec["type"]:
            self.err(path, "type %r, the spec says %r" % (s.get("type"), spec["type"]))
            return
        if spec.get("nullable") and not nullable:
            self.err(path, "the spec writes null here; the schema does not allow null")
        if "default" in spec:
            if "default" in s:
                if not self.same(s["default"], spec["default"]):
                    self.err(path, "default %r, the spec says %r" % (s["default"], spec["default"]))
            elif not spec.get("nullable"):
                self.err(path, "no default; the spec's is %r" % (spec["default"],))
        elif "default" in s:
            self.err(path, "default %r; the spec has none (derived or required)" % (s["default"],))
        for key in ("minimum", "maximum", "exclusiveMinimum"):
            if key in spec:
                if key in s:
                    if not self.same(s[key], spec[key]):
                        self.err(path, "%s %r, the spec says %r" % (key, s[key], spec[key]))
                elif "enum" in s and spec["type"] in ("integer", "number"):
                    bad = [v for v in s["enum"]
                           if (key == "minimum" and v < spec[key]) or
                           (key == "maximum" and v > spec[key]) or
                           (key == "exclusiveMinimum" and v <= spec[key])]
                    if bad:
                        self.err(path, "enum values %r outside the spec's %s %r" % (bad, key, spec[key]))
                else:
                    self.err(path, "no %s; the spec's is %r" % (key, spec[key]))
            elif key in s:
                self.err(path, "%s %r; the spec has none" % (key, s[key]))
        if spec["type"] == "string" and "enum" in spec:
            if s.get("enum") != spec["enum"]:
                self.err(path, "enum %r, the spec says %r" % (s.get("enum"), spec["enum"]))
        if spec["type"] == "array":
            if "enum" in spec:  # a set of names
                items, _ = self.resolve(s.get("items", {}))
                if items.get("enum") != spec["enum"]:
                    self.err(path, "items enum %r, the spec says %r" % (items.get("enum"), spec["enum"]))
                return
            for key in ("minItems", "maxItems"):
                want = spec[key]
                got = s.get(key, 0 if key == "minItems" else None)
                if got != want:
                    self.err(path, "%s %r, the spec says %r" % (key, got, want))
            if "items" not in s:
                self.err(path, "no items schema")
            else:
                self.field(path + "[]", spec["items"], s["items"])
        if spec["type"] == "object":
            self.props(path, spec["properties"], s)

    def props(self, path, fields, s):
        props = s.get("properties", {})
        if s.get("additionalProperties", True) is not False and \
                s.get("unevaluatedProperties", True) is not False:
            self.err(path or "params", "additional properties are allowed; the reader refuses them")
        for name in fields:
            if name not in props:
                self.err(path + "." + name if path else name, "not in the schema")
        for name in props:
            if name not in fields:
                self.err(path + "." + name if path else name, "in the schema, not in the spec")
        required = set(s.get("required", []))
        for name, f in fields.items():
            p = path + "." + name if path else name
            if bool(f.get("required")) != (name in required):
                self.err(p, "required in the %s only" % ("spec" if f.get("required") else "schema"))
            if name in props:
                self.field(p, f, props[name])


def main(argv):
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    with open(argv[1]) as f:
        api = yaml.safe_load(f)
    specs = json.loads(subprocess.run([argv[2]], check=True, capture_output=True,
                                      text=True).stdout)
    c = Checker(api)
    if set(specs) != set(SCHEMAS):
        c.err("kinds", "the table has %s, this check knows %s" % (sorted(specs), sorted(SCHEMAS)))
    schemas = api["components"]["schemas"]
    for kind, fields in specs.items():
        name = SCHEMAS.get(kind)
        if name not in schemas:
            c.err(kind, "no schema %s" % name)
            continue
        s, _ = c.resolve(schemas[name])
        before = len(c.errors)
        c.props("", fields, s)
        c.errors[before:] = ["%s (%s) %s" % (kind, name, e) for e in c.errors[before:]]
    for e in c.errors:
        print(e)
    print("params_spec_check: %d kinds, %d mismatches" % (len(specs), len(c.errors)))
    return 1 if c.errors else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
