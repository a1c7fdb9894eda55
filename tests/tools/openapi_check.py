#!/usr/bin/env python3
"""Check recorded voxeld HTTP responses against the OpenAPI 3.1 contract.

Usage:
  openapi_check.py SPEC.yaml LOG.jsonl [--require-all-paths]
  openapi_check.py SPEC.yaml --lint

LOG.jsonl has one JSON object per line, one per request the tests made:

  {"method": "GET",                    request method
   "path": "/v1/jobs/abc?wait=1",      raw request target (query kept)
   "status": 200,                      response status
   "content_type": "application/json", response Content-Type ("" or absent: none)
   "headers": {"location": "..."},     optional: response headers, lower-case names
   "body_file": "/tmp/x/123.body",     optional: file holding the response body;
                                       relative paths are relative to the log
   "request_body_file": "...",         optional: file holding the request body
   "request_content_type": "..."}      and its Content-Type

For each record the path (query stripped) is matched to one path template of
the spec (a {param} matches one non-empty segment; literal segments win over
templated ones), the method to an operation and the status to a response
(exact code, then "NXX", then "default"). 405 is accepted for any method a
known path does not have (checked against the 405 of the top-level extension
`x-general-responses`, the answers no operation lists); unknown paths must
answer 404, checked against its 404 (an Error body when it has none). Then: the Content-Type must
be one the response declares (media type only); a response without content
must have an empty body; a JSON body is validated (JSON Schema 2020-12) against
the response schema with $refs resolved in the whole spec; required response
headers must be present (when the record has "headers") and match their
schema. A request the daemon accepted (2xx) whose record has a JSON request
body must fit the operation's requestBody schema (bodies over 256 KiB are
not checked: too slow). A oneOf/anyOf with an
OpenAPI `discriminator` (JobRequest, Job: on `kind`) is reported as the
errors of the branch the discriminator value picks; --lint checks that each
discriminator maps every branch, that each branch fixes the property to its
value, and that a discriminator on `kind` maps exactly the x-kinds, each to
a branch with that kind's params (and stats) schema. voxeld-specific extras: Job bodies are checked against the kind's
entry in the top-level `x-kinds` extension (normalised params, stats, output
URLs (outputs with `requested_by: P` only when params[P] lists them; with
`numbered_by: P`, NAME_000.. when params[P] > 1; with `per_item_of: P`, once
per element of the array params.P (or `count` times for a blob reference
{"blob", "bytes", "count"}), named by formatting its name with n = 1,
2, ...; with `pattern: REGEX`, every output named like it, at least one;
with `present_when: {param: value}`, only when the params have it); an
output with `absent_when: {param: value}` (or a list of them, any) is not expected when
the job's params have that value), Info.kinds against `x-kinds`, /metrics
bodies against `x-metrics`.

Prints one line per failure and a summary line
  openapi: N responses checked, M failures, P/Q operations exercised
and exits 0 only when nothing failed (1 on failures, 2 on usage/spec errors).

Works with jsonschema 4.10 (Debian 12: RefResolver) and newer releases
(`referencing` registry); needs PyYAML.
"""

import argparse
import datetime
import json
import os
import re
import sys
import warnings
from urllib.parse import quote, unquote

import jsonschema
import yaml

warnings.simplefilter("ignore", DeprecationWarning)

HTTP_METHODS = ("get", "put", "post", "delete", "options", "head", "patch", "trace")
# Methods a server knows (RFC 9110 and PATCH): any other is 501 on any path.
KNOWN_METHODS = ("GET", "HEAD", "POST", "PUT", "DELETE", "CONNECT", "OPTIONS", "TRACE", "PATCH")
BASE_URI = "https://voxeld.invalid/openapi.yaml"
MAX_SCHEMA_ERRORS = 5
# Request bodies larger than this are not schema-checked (a 2 MB gregory
# `frames` array takes jsonschema seconds; test_timeouts sends dozens).
MAX_REQUEST_CHECK_BYTES = 256 * 1024
RFC3339 = re.compile(
    r"^\d{4}-\d{2}-\d{2}[Tt]\d{2}:\d{2}:\d{2}(\.\d+)?([Zz]|[+-]\d{2}:\d{2})$")


# --------------------------------------------------------------------------
# Spec helpers


def load_spec(path):
    with open(path, encoding="utf-8") as f:
        spec = yaml.safe_load(f)
    if not isinstance(spec, dict):
        raise ValueError("%s: not a YAML mapping" % path)
    return spec


def ptr_escape(seg):
    return str(seg).replace("~", "~0").replace("/", "~1")


def ptr_join(ptr, *segs):
    return ptr + "".join("/" + ptr_escape(s) for s in segs)


def ptr_get(doc, ptr):
    """Value at JSON pointer `ptr` ("" or "/a/b"); KeyError when absent."""
    node = doc
    if ptr == "":
        return node
    if not ptr.startswith("/"):
        raise KeyError(ptr)
    for raw in ptr[1:].split("/"):
        seg = raw.replace("~1", "/").replace("~0", "~")
        if isinstance(node, dict):
            if seg not in node:
                raise KeyError(ptr)
            node = node[seg]
        elif isinstance(node, list):
            try:
                node = node[int(seg)]
            except (ValueError, IndexError):
                raise KeyError(ptr) from None
        else:
            raise KeyError(ptr)
    return node


def ref_to_ptr(ref):
    """'#/components/x' -> '/components/x'; None for non-local refs."""
    if not isinstance(ref, str) or not ref.startswith("#"):
        return None
    return unquote(ref[1:])


def deref(spec, node, ptr):
    """Follows a chain of $ref objects; returns (node, pointer of node)."""
    seen = set()
    while isinstance(node, dict) and "$ref" in node and isinstance(node["$ref"], str):
        target = ref_to_ptr(node["$ref"])
        if target is None or target in seen:
            raise KeyError(node["$ref"])
        seen.add(target)
        node, ptr = ptr_get(spec, target), target
    return node, ptr


def status_keys(responses):
    return {str(k).upper() if "X" in str(k).upper() else str(k): k for k in responses}


def media_type(ct):
    if not ct:
        return ""
    return ct.split(";", 1)[0].strip().lower()


def is_json_media(mt):
    return mt == "application/json" or mt.endswith("+json")


def media_matches(declared, actual):
    d = media_type(declared)
    if d == actual or d == "*/*":
        return True
    if d.endswith("/*"):
        return actual.split("/", 1)[0] == d[:-2]
    return False


def make_format_checker():
    fc = jsonschema.FormatChecker(formats=())

    @fc.checks("date-time", raises=ValueError)
    def _date_time(value):
        if not isinstance(value, str):
            return True
        if not RFC3339.match(value):
            return False
        v = value.replace("z", "Z").replace("t", "T")
        datetime.datetime.fromisoformat(v.replace("Z", "+00:00"))
        return True

    return fc


class Schemas:
    """Draft 2020-12 validators for schemas at JSON pointers of the spec, with
    $ref resolved against the whole spec document."""

    def __init__(self, spec):
        self.spec = spec
        self.fc = make_format_checker()
        self.cache = {}
        self.registry = None
        try:
            import referencing  # jsonschema >= 4.18
            import referencing.jsonschema

            res = referencing.Resource.from_contents(
                spec, default_specification=referencing.jsonschema.DRAFT202012)
            registry = referencing.Registry().with_resource(BASE_URI, res)
            jsonschema.Draft202012Validator({}, registry=registry)
            self.registry = registry
        except (ImportError, TypeError):
            self.resolver = jsonschema.RefResolver(BASE_URI, spec)

    def validator(self, ptr):
        v = self.cache.get(ptr)
        if v is None:
            schema = {"$ref": BASE_URI + "#" + quote(ptr, safe="/~")}
            if self.registry is not None:
                v = jsonschema.Draft202012Validator(
                    schema, registry=self.registry, format_checker=self.fc)
            else:
                v = jsonschema.Draft202012Validator(
                    schema, resolver=self.resolver, format_checker=self.fc)
            self.cache[ptr] = v
        return v

    def errors(self, ptr, instance):
        """Human-readable schema errors (list of strings). A oneOf/anyOf with
        an OpenAPI `discriminator` is reported as the errors of the branch
        the discriminator picks (or as a bad discriminator value), not as
        "valid under none of the given schemas"."""
        found = sorted(self.flat_errors(self.validator(ptr).iter_errors(instance), []),
                       key=lambda pm: (len(pm[0]), list(map(str, pm[0]))))
        out = []
        for path, msg in found:
            where = "$" + "".join("[%s]" % json.dumps(p) if isinstance(p, str) else "[%d]" % p
                                  for p in path)
            if len(msg) > 300:
                msg = msg[:300] + "..."
            out.append("%s: %s" % (where, msg))
        return out

    def flat_errors(self, errs, base):
        """(path, message) of each error; paths are prefixed by `base`."""
        for e in errs:
            path = base + list(e.absolute_path)
            picked = self.discriminated(e)
            if picked is not None:
                branch_ptr, problem = picked
                if problem is not None:
                    yield path + problem[0], problem[1]
                    continue
                sub = list(self.flat_errors(self.validator(branch_ptr).iter_errors(e.instance),
                                            path))
                if sub:
                    yield from sub
                    continue
                # The picked branch fits: the oneOf failed otherwise (the
                # instance fits several branches); say so below.
            msg = e.message
            if e.context:  # anyOf/oneOf: say what the closest branch wanted
                best = jsonschema.exceptions.best_match(e.context)
                msg += " (%s)" % best.message
            yield path, msg

    def discriminated(self, e):
        """For a failed oneOf/anyOf whose schema has a `discriminator`:
        (pointer of the branch it picks, None), or (None, (path, message))
        when the instance has no usable discriminator value. Else None."""
        schema = e.schema if isinstance(e.schema, dict) else {}
        d = schema.get("discriminator")
        if e.validator not in ("oneOf", "anyOf") or not isinstance(d, dict):
            return None
        prop = d.get("propertyName")
        if not isinstance(prop, str) or not isinstance(e.instance, dict):
            return None
        mapping = discriminator_mapping(schema)
        if prop not in e.instance:
            return None, ([], "%r is required (the discriminator)" % prop)
        value = e.instance[prop]
        ref = mapping.get(value) if isinstance(value, str) else None
        target = ref_to_ptr(ref)
        if target is None:
            return None, ([prop], "%s is not a value of the discriminator %s (%s)"
                          % (json.dumps(value), prop, ", ".join(sorted(mapping))))
        return target, None


def discriminator_mapping(schema):
    """value -> $ref of a schema's discriminator: its `mapping`, and for the
    oneOf/anyOf $refs it does not name, the last segment of the ref (the
    OpenAPI implicit mapping)."""
    d = schema.get("discriminator") or {}
    mapping = {k: v for k, v in (d.get("mapping") or {}).items() if isinstance(v, str)}
    named = set(mapping.values())
    for sub in (schema.get("oneOf") or schema.get("anyOf") or []):
        ref = sub.get("$ref") if isinstance(sub, dict) else None
        if isinstance(ref, str) and ref not in named:
            mapping.setdefault(ref.rsplit("/", 1)[-1], ref)
    return mapping


def schema_refs(schema):
    """$refs a schema is made of (itself, or its allOf members)."""
    refs = []
    if isinstance(schema, dict):
        if isinstance(schema.get("$ref"), str):
            refs.append(schema["$ref"])
        for sub in schema.get("allOf", []) or []:
            if isinstance(sub, dict) and isinstance(sub.get("$ref"), str):
                refs.append(sub["$ref"])
    return refs


def split_template(t):
    return t.strip("/").split("/") if t != "/" else [""]


def is_param_seg(seg):
    return len(seg) > 2 and seg[0] == "{" and seg[-1] == "}" and "{" not in seg[1:-1]


def match_path(templates, path):
    """Returns (template, params) of the best match, None when none matches,
    or raises ValueError when two templates match equally well."""
    segs = path[1:].split("/") if path != "/" else [""]
    if not path.startswith("/"):
        return None
    if path != "/" and path.endswith("/"):
        return None  # paths are not normalised: a trailing slash names nothing
    best, best_key, tie = None, None, False
    for t in templates:
        tsegs = split_template(t)
        if len(tsegs) != len(segs):
            continue
        params, key, ok = {}, [], True
        for ts, s in zip(tsegs, segs):
            if is_param_seg(ts):
                if s == "":
                    ok = False
                    break
                params[ts[1:-1]] = unquote(s)
                key.append(0)
            elif ts == s:
                key.append(1)
            else:
                ok = False
                break
        if not ok:
            continue
        if best_key is None or key > best_key:
            best, best_key, tie = (t, params), key, False
        elif key == best_key:
            tie = True
    if tie:
        raise ValueError("path matches several templates equally")
    return best


# --------------------------------------------------------------------------
# Log checking


class Checker:
    def __init__(self, spec, log_path):
        self.spec = spec
        self.schemas = Schemas(spec)
        self.log_path = log_path
        self.log_dir = os.path.dirname(os.path.abspath(log_path or "."))
        self.fail_hook = None
        self.paths = spec.get("paths") or {}
        self.failures = 0
        self.checked = 0
        self.bodies_missing = 0
        self.requests_skipped = 0
        self.exercised = set()
        self.kinds = spec.get("x-kinds") or {}

    # -- reporting
    def fail(self, where, msg):
        self.failures += 1
        if self.fail_hook is not None:
            self.fail_hook("%s: %s" % (where, msg))
        else:
            print("%s: %s" % (where, msg))

    # -- operations
    def operations(self):
        ops = []
        for t, item in self.paths.items():
            item, _ = deref(self.spec, item, ptr_join("/paths", t))
            for m in HTTP_METHODS:
                if isinstance(item.get(m), dict):
                    ops.append((t, m))
        return ops

    def run(self):
        with open(self.log_path, encoding="utf-8") as f:
            for lineno, line in enumerate(f, 1):
                if not line.strip():
                    continue
                where = "%s:%d" % (self.log_path, lineno)
                try:
                    rec = json.loads(line)
                    if not isinstance(rec, dict):
                        raise ValueError("not an object")
                    method = str(rec["method"])  # case-sensitive (RFC 9110 9.1)
                    raw = str(rec["path"])
                    status = int(rec["status"])
                except (ValueError, KeyError, TypeError) as e:
                    self.checked += 1
                    self.fail(where, "bad log record: %s" % e)
                    continue
                self.checked += 1
                self.check(rec, "%s: %s %s %d" % (where, method, raw, status),
                           method, raw, status)

    def load_body(self, rec, where):
        bf = rec.get("body_file")
        if not bf:
            return None
        if not os.path.isabs(bf):
            bf = os.path.join(self.log_dir, bf)
        try:
            with open(bf, "rb") as f:
                return f.read()
        except OSError:
            self.bodies_missing += 1
            return None

    def check(self, rec, where, method, raw, status):
        path = raw.split("?", 1)[0].split("#", 1)[0]
        headers = rec.get("headers")
        if headers is not None and not isinstance(headers, dict):
            self.fail(where, "bad log record: headers is not an object")
            headers = None
        if headers is not None:
            headers = {str(k).lower(): str(v) for k, v in headers.items()}
        body = self.load_body(rec, where)
        ct = media_type(rec.get("content_type") or "")

        if method not in KNOWN_METHODS:
            if status != 501:
                self.fail(where, "unknown method %s answered %d, expected 501" % (method, status))
                return
            gen = self.general_response(501)
            if gen is None or body is None:
                self.check_error_body(where, method, ct, body)
            else:
                self.check_response(where, method, None, gen[0], gen[1], ct, headers, body, {})
            return
        try:
            m = match_path(list(self.paths), path)
        except ValueError as e:
            self.fail(where, str(e))
            return
        if m is None:
            if status != 404:
                self.fail(where, "unknown path answered %d, expected 404" % status)
                return
            gen = self.general_response(404)
            if gen is None or method == "HEAD" or body is None:
                self.check_error_body(where, method, ct, body)
            else:
                self.check_response(where, method, None, gen[0], gen[1], ct, headers, body, {})
            return
        template, params = m
        item, item_ptr = deref(self.spec, self.paths[template], ptr_join("/paths", template))
        lookup = method.lower()
        # HEAD is answered wherever GET is (the spec's general rules).
        if lookup == "head" and not isinstance(item.get("head"), dict) \
                and isinstance(item.get("get"), dict):
            lookup = "get"
        op = item.get(lookup) if lookup in HTTP_METHODS else None
        if method == "OPTIONS" and not isinstance(op, dict) and status == 204:
            # answered on every path (Conventions): Allow lists the path's methods
            if headers is not None and "allow" not in headers:
                self.fail(where, "OPTIONS 204 without Allow")
            return
        if not isinstance(op, dict):
            gen = self.general_response(status) if status not in (404, 405) else None
            if gen is not None:  # framing, timeouts, limits: answered before the method
                self.check_response(where, method, None, gen[0], gen[1], ct, headers, body, params)
                return
            if status != 405:
                self.fail(where, "%s is not an operation of %s (only 405 or x-general-responses "
                          "are allowed), got %d" % (method, template, status))
                return
            gen = self.general_response(405)
            if gen is None:
                self.check_error_body(where, method, ct, body)
                return
            resp, resp_ptr = gen
            self.check_response(where, method, None, resp, resp_ptr, ct, headers, body, params)
            if headers is not None and "allow" in headers:
                allowed = {a.strip().upper() for a in headers["allow"].split(",") if a.strip()}
                allowed -= {"HEAD", "OPTIONS"}
                want = {mm.upper() for mm in HTTP_METHODS if isinstance(item.get(mm), dict)}
                if allowed != want:
                    self.fail(where, "Allow: %s, expected the methods %s"
                              % (headers["allow"], ", ".join(sorted(want))))
            return
        op_ptr = ptr_join(item_ptr, lookup)
        self.exercised.add((template, lookup))
        responses = op.get("responses") or {}
        keys = status_keys(responses)
        key = None
        for k in (str(status), "%dXX" % (status // 100), "default"):
            if k in keys:
                key = keys[k]
                break
        if key is None:
            gen = self.general_response(status) if status not in (404, 405, 501) else None
            if gen is not None:  # an answer any path may give (x-general-responses)
                self.check_response(where, method, op, gen[0], gen[1], ct, headers, body, params)
                return
            self.fail(where, "status %d is not a response of %s (%s)"
                      % (status, op.get("operationId", "?"), ", ".join(sorted(map(str, responses)))))
            return
        resp_ptr = ptr_join(op_ptr, "responses", key)
        resp, resp_ptr = deref(self.spec, responses[key], resp_ptr)
        self.check_response(where, method, op, resp, resp_ptr, ct, headers, body, params)
        if 200 <= status < 300:
            self.check_request(where, rec, op, op_ptr)

    def check_request(self, where, rec, op, op_ptr):
        """A request the daemon accepted (2xx) must fit the operation's
        requestBody: its JSON body (record fields request_body_file and
        request_content_type) against the schema, e.g. a job request
        against the JobRequest branch its `kind` picks."""
        bf = rec.get("request_body_file")
        if not bf or not isinstance(op.get("requestBody"), dict):
            return
        rb, rb_ptr = deref(self.spec, op["requestBody"], ptr_join(op_ptr, "requestBody"))
        rct = media_type(rec.get("request_content_type") or "")
        if not is_json_media(rct):
            return
        content = rb.get("content") or {}
        mt = next((d for d in content if media_matches(d, rct)), None)
        if mt is None:
            self.fail(where, "accepted a request body of type %s, not declared (declared: %s)"
                      % (rct, ", ".join(content)))
            return
        if "schema" not in (content[mt] or {}):
            return
        if not os.path.isabs(bf):
            bf = os.path.join(self.log_dir, bf)
        try:
            if os.path.getsize(bf) > MAX_REQUEST_CHECK_BYTES:
                self.requests_skipped += 1
                return
            with open(bf, "rb") as f:
                data = f.read()
            doc = json.loads(data.decode("utf-8"))
        except OSError:
            self.bodies_missing += 1
            return
        except (UnicodeDecodeError, ValueError) as e:
            self.fail(where, "accepted a request body that is not JSON: %s" % e)
            return
        sptr = ptr_join(rb_ptr, "content", mt, "schema")
        errs = self.schemas.errors(sptr, doc)
        for e in errs[:MAX_SCHEMA_ERRORS]:
            self.fail(where, "accepted request body %s" % e)

    def general_response(self, status):
        """(response, pointer) of x-general-responses[status], or None."""
        ptr = ptr_join("/x-general-responses", str(status))
        try:
            return deref(self.spec, ptr_get(self.spec, ptr), ptr)
        except KeyError:
            return None

    def check_error_body(self, where, method, ct, body):
        if method == "HEAD" or body is None:
            return
        if not is_json_media(ct):
            self.fail(where, "expected an Error JSON body, Content-Type is %r" % (ct or "none"))
            return
        self.check_json(where, body, "/components/schemas/Error", None)

    def check_response(self, where, method, op, resp, resp_ptr, ct, headers, body, params):
        content = resp.get("content") or {}
        if headers is not None and body is not None and method != "HEAD" \
                and "content-length" in headers:
            try:
                cl = int(headers["content-length"])
                if cl != len(body):
                    self.fail(where, "Content-Length %d but the body has %d bytes"
                              % (cl, len(body)))
            except ValueError:
                self.fail(where, "bad Content-Length %r" % headers["content-length"])

        doc = None
        if not content:
            if body and method != "HEAD":
                self.fail(where, "the response has no content but the body has %d bytes"
                          % len(body))
        else:
            declared = list(content)
            if not ct:
                self.fail(where, "no Content-Type (declared: %s)" % ", ".join(declared))
            else:
                mt = next((d for d in declared if media_matches(d, ct)), None)
                if mt is None:
                    self.fail(where, "Content-Type %s is not declared (declared: %s)"
                              % (ct, ", ".join(declared)))
                elif method != "HEAD" and body is not None:
                    media = content[mt] or {}
                    if is_json_media(ct) and "schema" in media:
                        schema_ptr = ptr_join(resp_ptr, "content", mt, "schema")
                        doc = self.check_json(where, body, schema_ptr, media["schema"])
                    elif ct == "image/png" and "content-range" not in (headers or {}) \
                            and not body.startswith(b"\x89PNG\r\n\x1a\n"):
                        self.fail(where, "the body is not a PNG file")
                    elif op is not None and op.get("x-metrics") and ct == "text/plain":
                        self.check_metrics(where, op["x-metrics"], body)

        if headers is not None:
            self.check_headers(where, resp, resp_ptr, headers, doc, params)

    def check_json(self, where, body, schema_ptr, schema):
        if not body:
            self.fail(where, "empty body, expected JSON")
            return None
        try:
            doc = json.loads(body.decode("utf-8"))
        except (UnicodeDecodeError, ValueError) as e:
            self.fail(where, "body is not JSON: %s" % e)
            return None
        errs = self.schemas.errors(schema_ptr, doc)
        for e in errs[:MAX_SCHEMA_ERRORS]:
            self.fail(where, "body %s" % e)
        if len(errs) > MAX_SCHEMA_ERRORS:
            print("%s: ... and %d more schema errors" % (where, len(errs) - MAX_SCHEMA_ERRORS))
        if errs:
            return None
        refs = schema_refs(schema)
        if "#/components/schemas/Job" in refs:
            self.check_job(where, doc, "$")
        elif "#/components/schemas/JobList" in refs:
            for i, job in enumerate(doc.get("items", [])):
                self.check_job(where, job, "$.items[%d]" % i)
        elif "#/components/schemas/Info" in refs and self.kinds:
            got = sorted(k.get("name") for k in doc.get("kinds", []))
            want = sorted(self.kinds)
            if got != want:
                self.fail(where, "body $.kinds lists %s, x-kinds has %s" % (got, want))
        return doc

    def check_job(self, where, job, at):
        if not self.kinds:
            return
        kind = job.get("kind")
        k = self.kinds.get(kind)
        if not isinstance(k, dict):
            self.fail(where, "body %s.kind: %r is not in x-kinds" % (at, kind))
            return
        base = ptr_join("/x-kinds", kind)
        if "params" in k:
            for e in self.schemas.errors(ptr_join(base, "params"), job.get("params"))[:MAX_SCHEMA_ERRORS]:
                self.fail(where, "body %s.params (kind %s): %s" % (at, kind, e))
            try:
                ps, _ = deref(self.spec, k["params"], ptr_join(base, "params"))
                missing = sorted(set((ps.get("properties") or {})) - set(job.get("params") or {}))
            except KeyError:
                missing = []
            if missing:
                self.fail(where, "body %s.params is not normalised: missing %s"
                          % (at, ", ".join(missing)))
        state = job.get("state")
        if state == "succeeded" and "stats" in k:
            for e in self.schemas.errors(ptr_join(base, "stats"), job.get("stats"))[:MAX_SCHEMA_ERRORS]:
                self.fail(where, "body %s.stats (kind %s): %s" % (at, kind, e))
        if state == "succeeded":
            # An output with `absent_when: {param: value}` is not written
            # when the job's (normalised) params have that value.
            params = job.get("params") if isinstance(job.get("params"), dict) else {}
            outputs = job.get("outputs") or {}

            def holds(cond):
                return (isinstance(cond, dict) and bool(cond)
                        and all(params.get(p) == v for p, v in cond.items()))
            want = []
            for o in k.get("outputs") or []:
                # `absent_when`: one {param: value} condition or a list of
                # them (any); `present_when`: written only when it holds.
                aw = o.get("absent_when")
                if any(holds(c) for c in (aw if isinstance(aw, list) else [aw])):
                    continue
                if "present_when" in o and not holds(o["present_when"]):
                    continue
                # `pattern: REGEX`: the outputs whose names match it (bricks).
                pat = o.get("pattern")
                if isinstance(pat, str):
                    matched = [n for n in outputs if re.fullmatch(pat, n)]
                    if not matched:
                        self.fail(where, "body %s.outputs has none named like %s" % (at, pat))
                    want += matched
                    continue
                # `per_item_of: P`: once per element of the array params[P],
                # the name formatted with n = 1, 2, ...
                pi = o.get("per_item_of")
                if isinstance(pi, str):
                    items = params.get(pi)
                    # a large array kept as a blob: {"blob", "bytes", "count"}
                    if isinstance(items, dict) and isinstance(items.get("count"), int):
                        items = [None] * items["count"]
                    if isinstance(items, list):
                        want += [o.get("name", "").format(n=i + 1) for i in range(len(items))]
                    continue
                # `requested_by: P`: written only when params[P] (a list) names it.
                rb = o.get("requested_by")
                if isinstance(rb, str) and o.get("name") not in (params.get(rb) or []):
                    continue
                # `numbered_by: P`: NAME_000 .. when params[P] > 1, else NAME.
                nb = o.get("numbered_by")
                count = params.get(nb) if isinstance(nb, str) else None
                if isinstance(count, int) and not isinstance(count, bool) and count > 1:
                    want += ["%s_%03d" % (o.get("name"), i) for i in range(count)]
                else:
                    want.append(o.get("name"))
            if sorted(outputs) != sorted(want):
                self.fail(where, "body %s.outputs has %s, kind %s declares %s"
                          % (at, sorted(outputs), kind, sorted(want)))
            for name, url in outputs.items():
                if url != "/v1/jobs/%s/result/%s" % (job.get("id"), name):
                    self.fail(where, "body %s.outputs[%s]: %r is not /v1/jobs/%s/result/%s"
                              % (at, json.dumps(name), url, job.get("id"), name))

    def check_metrics(self, where, metrics, body):
        text = body.decode("utf-8", "replace")
        types = dict(re.findall(r"^# TYPE (\S+) (\S+)\s*$", text, re.M))
        cluster = any(n.startswith("voxeld_cluster_") for n in types)
        listed = {m.get("name") for m in metrics}
        for name in sorted(set(types) - listed):
            self.fail(where, "metric family %s is not in x-metrics" % name)
        for m in metrics:
            name, typ = m.get("name"), m.get("type")
            if m.get("cluster") and not cluster:
                continue
            if name not in types:
                self.fail(where, "metric family %s is missing (no # TYPE line)" % name)
            elif typ and types[name] != typ:
                self.fail(where, "metric family %s has type %s, expected %s"
                          % (name, types[name], typ))

    def check_headers(self, where, resp, resp_ptr, headers, doc, params):
        for name, h in (resp.get("headers") or {}).items():
            try:
                h, h_ptr = deref(self.spec, h, ptr_join(resp_ptr, "headers", name))
            except KeyError:
                continue
            value = headers.get(name.lower())
            if value is None:
                if h.get("required"):
                    self.fail(where, "missing required header %s" % name)
                continue
            if name.lower() == "content-type":
                continue
            schema = h.get("schema")
            if isinstance(schema, dict):
                s, _ = deref(self.spec, schema, ptr_join(h_ptr, "schema"))
                inst = value
                t = s.get("type")
                try:
                    if t == "integer":
                        inst = int(value.strip())
                    elif t == "number":
                        inst = float(value.strip())
                except ValueError:
                    self.fail(where, "header %s: %r is not a%s %s"
                              % (name, value, "n" if t == "integer" else "", t))
                    continue
                for e in self.schemas.errors(ptr_join(h_ptr, "schema"), inst):
                    self.fail(where, "header %s: %r: %s" % (name, value, e.split(": ", 1)[-1]))
            lname = name.lower()
            if lname == "location" and isinstance(doc, dict) and isinstance(doc.get("id"), str):
                if not value.rstrip("/").endswith("/" + doc["id"]):
                    self.fail(where, "Location %s does not name the body's id %s"
                              % (value, doc["id"]))
            if lname == "content-disposition" and "jid" in params:
                prefix = 'filename="%s-' % params["jid"]
                if "name" in params:
                    prefix += params["name"] + "."
                if prefix not in value:
                    self.fail(where, "Content-Disposition %s: expected %s...\"" % (value, prefix))


# --------------------------------------------------------------------------
# Lint


def lint(spec_path):
    problems = []
    try:
        spec = load_spec(spec_path)
    except (OSError, ValueError, yaml.YAMLError) as e:
        print("openapi lint: cannot load %s: %s" % (spec_path, e))
        return 2

    def problem(msg):
        problems.append(msg)

    ver = str(spec.get("openapi", ""))
    if not re.match(r"^3\.1\.\d+$", ver):
        problem("openapi is %r, expected 3.1.x" % ver)
    info = spec.get("info") or {}
    for k in ("title", "version"):
        if not info.get(k):
            problem("info.%s is missing" % k)

    # Every $ref resolves.
    def walk(node, ptr):
        if isinstance(node, dict):
            ref = node.get("$ref")
            if isinstance(ref, str):
                target = ref_to_ptr(ref)
                if target is None:
                    problem("%s: $ref %s is not a local reference" % (ptr or "/", ref))
                else:
                    try:
                        ptr_get(spec, target)
                    except KeyError:
                        problem("%s: $ref %s does not resolve" % (ptr or "/", ref))
            for k, v in node.items():
                walk(v, ptr_join(ptr, k))
        elif isinstance(node, list):
            for i, v in enumerate(node):
                walk(v, ptr_join(ptr, i))

    nbefore = len(problems)
    walk(spec, "")
    if len(problems) > nbefore:  # the rest needs resolvable refs
        return report_lint(problems, 0)

    schemas = Schemas(spec)
    validator_cls = jsonschema.Draft202012Validator
    tags = {t.get("name") for t in spec.get("tags") or [] if isinstance(t, dict)}
    schemes = set(((spec.get("components") or {}).get("securitySchemes") or {}))

    def check_security(sec, where):
        for req in sec or []:
            for name in req or {}:
                if name not in schemes:
                    problem("%s: security scheme %s is not defined" % (where, name))

    def check_schema_at(ptr, where):
        try:
            s = ptr_get(spec, ptr)
            validator_cls.check_schema(s)
        except jsonschema.exceptions.SchemaError as e:
            problem("%s: invalid schema: %s" % (where, e.message))
            return False
        return True

    def check_example(value, schema_ptr, where):
        for e in schemas.errors(schema_ptr, value)[:MAX_SCHEMA_ERRORS]:
            problem("%s: example does not match its schema: %s" % (where, e))

    # Job examples must also fit their kind's x-kinds entry.
    job_checker = Checker(spec, None)
    job_checker.fail_hook = problem

    def check_media_example(value, sptr, schema, where):
        n = len(problems)
        check_example(value, sptr, where)
        if len(problems) == n and "#/components/schemas/Job" in schema_refs(schema) \
                and isinstance(value, dict):
            job_checker.check_job(where + " example", value, "$")

    def check_media(media, mptr, where, mt):
        if not isinstance(media, dict) or "schema" not in media:
            return
        sptr = ptr_join(mptr, "schema")
        if not check_schema_at(sptr, where):
            return
        if not is_json_media(media_type(mt)):
            return
        if "example" in media:
            check_media_example(media["example"], sptr, media["schema"], where + " example")
        for name, ex in (media.get("examples") or {}).items():
            ex, _ = deref(spec, ex, ptr_join(mptr, "examples", name))
            if isinstance(ex, dict) and "value" in ex:
                check_media_example(ex["value"], sptr, media["schema"],
                                    "%s examples.%s" % (where, name))

    def check_param_or_header(p, pptr, where):
        if "schema" in p:
            sptr = ptr_join(pptr, "schema")
            if check_schema_at(sptr, where) and "example" in p:
                check_example(p["example"], sptr, where + " example")

    check_security(spec.get("security"), "security")
    op_ids = {}
    nops = 0
    templates = list((spec.get("paths") or {}).keys())
    shapes = {}
    for t in templates:
        if not t.startswith("/"):
            problem("path %s does not start with /" % t)
        shape = "/".join("{}" if is_param_seg(s) else s for s in split_template(t))
        if shape in shapes:
            problem("paths %s and %s are the same template" % (shapes[shape], t))
        shapes[shape] = t
        item, item_ptr = deref(spec, spec["paths"][t], ptr_join("/paths", t))
        names = re.findall(r"\{([^{}/]*)\}", t)
        if len(set(names)) != len(names):
            problem("%s: a path parameter appears twice" % t)
        item_params = {}
        for i, p in enumerate(item.get("parameters") or []):
            pp, pptr = deref(spec, p, ptr_join(item_ptr, "parameters", i))
            item_params[(pp.get("name"), pp.get("in"))] = pp
            check_param_or_header(pp, pptr, "%s parameter %s" % (t, pp.get("name")))
        for m in HTTP_METHODS:
            op = item.get(m)
            if op is None:
                continue
            nops += 1
            where = "%s %s" % (m.upper(), t)
            op_ptr = ptr_join(item_ptr, m)
            if not isinstance(op, dict):
                problem("%s: not an operation object" % where)
                continue
            oid = op.get("operationId")
            if not oid:
                problem("%s: no operationId" % where)
            elif oid in op_ids:
                problem("%s: operationId %s is also used by %s" % (where, oid, op_ids[oid]))
            else:
                op_ids[oid] = where
            if not op.get("summary"):
                problem("%s: no summary" % where)
            if not op.get("tags"):
                problem("%s: no tags" % where)
            for tag in op.get("tags") or []:
                if tags and tag not in tags:
                    problem("%s: tag %s is not declared in tags" % (where, tag))
            check_security(op.get("security"), where)
            params = dict(item_params)
            for i, p in enumerate(op.get("parameters") or []):
                pp, pptr = deref(spec, p, ptr_join(op_ptr, "parameters", i))
                params[(pp.get("name"), pp.get("in"))] = pp
                check_param_or_header(pp, pptr, "%s parameter %s" % (where, pp.get("name")))
            declared = {n for (n, loc) in params if loc == "path"}
            for n in names:
                if n not in declared:
                    problem("%s: path parameter {%s} is not declared" % (where, n))
            for (n, loc), pp in params.items():
                if loc == "path":
                    if n not in names:
                        problem("%s: path parameter %s is not in the template" % (where, n))
                    if pp.get("required") is not True:
                        problem("%s: path parameter %s must be required: true" % (where, n))
            rb = op.get("requestBody")
            if rb is not None:
                rb, rb_ptr = deref(spec, rb, ptr_join(op_ptr, "requestBody"))
                for mt, media in (rb.get("content") or {}).items():
                    check_media(media, ptr_join(rb_ptr, "content", mt),
                                "%s request %s" % (where, mt), mt)
            responses = op.get("responses") or {}
            if not responses:
                problem("%s: no responses" % where)
            for code, r in responses.items():
                if not re.match(r"^([1-5][0-9][0-9]|[1-5]XX|default)$", str(code)):
                    problem("%s: bad response key %r" % (where, code))
                r, r_ptr = deref(spec, r, ptr_join(op_ptr, "responses", code))
                if not r.get("description"):
                    problem("%s %s: no description" % (where, code))
                for mt, media in (r.get("content") or {}).items():
                    check_media(media, ptr_join(r_ptr, "content", mt),
                                "%s %s %s" % (where, code, mt), mt)
                for hn, h in (r.get("headers") or {}).items():
                    h, h_ptr = deref(spec, h, ptr_join(r_ptr, "headers", hn))
                    check_param_or_header(h, h_ptr, "%s %s header %s" % (where, code, hn))

    comps = spec.get("components") or {}
    for name in comps.get("schemas") or {}:
        sptr = ptr_join("/components/schemas", name)
        if not check_schema_at(sptr, "schema " + name):
            continue
        for i, ex in enumerate(comps["schemas"][name].get("examples") or []):
            check_example(ex, sptr, "schema %s examples[%d]" % (name, i))

    # Discriminators: every branch is mapped and fixes the property to its
    # value; a discriminator on `kind` maps exactly the x-kinds, each to a
    # branch whose params (and stats) are that kind's.
    xk = spec.get("x-kinds") if isinstance(spec.get("x-kinds"), dict) else {}
    for name, sch in (comps.get("schemas") or {}).items():
        if isinstance(sch, dict) and "discriminator" in sch:
            check_discriminator(spec, name, sch, xk, problem)

    # Defaults inside schemas must be valid for their schema.
    def walk_defaults(node, ptr):
        if isinstance(node, dict):
            if "default" in node and ("type" in node or "$ref" in node or "enum" in node):
                check_example(node["default"], ptr, "%s default" % ptr)
            for k, v in node.items():
                if k not in ("default", "examples", "example", "const", "enum"):
                    walk_defaults(v, ptr_join(ptr, k))
        elif isinstance(node, list):
            for i, v in enumerate(node):
                walk_defaults(v, ptr_join(ptr, i))

    walk_defaults(comps.get("schemas") or {}, "/components/schemas")
    walk_defaults(comps.get("parameters") or {}, "/components/parameters")

    for name, r in (comps.get("responses") or {}).items():
        if not r.get("description"):
            problem("response %s: no description" % name)
        for mt, media in (r.get("content") or {}).items():
            check_media(media, ptr_join("/components/responses", name, "content", mt),
                        "response %s %s" % (name, mt), mt)
    general = spec.get("x-general-responses")
    if not isinstance(general, dict):
        problem("x-general-responses is missing (the checker uses its 404 and 405)")
        general = {}
    for code in ("404", "405"):
        if code not in general:
            problem("x-general-responses.%s is missing (the checker uses it)" % code)
    for code, r in general.items():
        where = "x-general-responses.%s" % code
        r, r_ptr = deref(spec, r, ptr_join("/x-general-responses", code))
        if not isinstance(r, dict) or not r.get("description"):
            problem("%s: no description" % where)
            continue
        for mt, media in (r.get("content") or {}).items():
            check_media(media, ptr_join(r_ptr, "content", mt), "%s %s" % (where, mt), mt)
        for hn, h in (r.get("headers") or {}).items():
            h, h_ptr = deref(spec, h, ptr_join(r_ptr, "headers", hn))
            check_param_or_header(h, h_ptr, "%s header %s" % (where, hn))

    # voxeld extensions.
    kinds = spec.get("x-kinds")
    if kinds is not None:
        if not isinstance(kinds, dict):
            problem("x-kinds is not a mapping")
        else:
            for kname, k in kinds.items():
                where = "x-kinds.%s" % kname
                if not isinstance(k, dict):
                    problem("%s: not a mapping" % where)
                    continue
                for key in ("summary", "params", "stats", "outputs"):
                    if key not in k:
                        problem("%s: no %s" % (where, key))
                for key in ("params", "stats"):
                    if key in k:
                        check_schema_at(ptr_join("/x-kinds", kname, key), "%s.%s" % (where, key))
                outs = k.get("outputs") or []
                if not outs:
                    problem("%s: no outputs" % where)
                for i, o in enumerate(outs):
                    if not isinstance(o, dict) or not all(o.get(f) for f in
                                                          ("name", "content_type", "extension")):
                        problem("%s.outputs[%d]: needs name, content_type, extension" % (where, i))
    return report_lint(problems, nops, len(comps.get("schemas") or {}))


def fixed_value(schema):
    """The one value a property schema allows (const or a one-item enum)."""
    if "const" in schema:
        return schema["const"]
    if isinstance(schema.get("enum"), list) and len(schema["enum"]) == 1:
        return schema["enum"][0]
    return None


def branch_ref(node, key):
    """The $ref of properties.KEY of a branch (or of its if/then), if any."""
    for holder in (node, (node.get("then") or {}) if isinstance(node, dict) else {}):
        prop = ((holder.get("properties") or {}).get(key)) if isinstance(holder, dict) else None
        if isinstance(prop, dict) and isinstance(prop.get("$ref"), str):
            return prop["$ref"]
    return None


def check_discriminator(spec, name, sch, kinds, problem):
    where = "schema %s discriminator" % name
    d = sch["discriminator"]
    prop = d.get("propertyName") if isinstance(d, dict) else None
    if not isinstance(prop, str) or not prop:
        problem("%s: no propertyName" % where)
        return
    branches = sch.get("oneOf") or sch.get("anyOf")
    if not isinstance(branches, list) or not branches:
        problem("%s: needs oneOf or anyOf" % where)
        return
    refs = [b.get("$ref") for b in branches if isinstance(b, dict)]
    if None in refs or len(refs) != len(branches):
        problem("%s: every oneOf/anyOf branch must be a $ref" % where)
        return
    for v, ref in ((d.get("mapping") or {}).items()):
        if ref not in refs:
            problem("%s: mapping %s -> %s is not a oneOf/anyOf branch" % (where, v, ref))
    mapping = discriminator_mapping(sch)
    for v, ref in mapping.items():
        try:
            node, _ = deref(spec, {"$ref": ref}, name)
        except KeyError:
            continue  # reported as an unresolved $ref
        reqd = set(node.get("required") or [])
        pschema = (node.get("properties") or {}).get(prop)
        if prop not in reqd or not isinstance(pschema, dict):
            problem("%s: branch %s must require and declare %s" % (where, ref, prop))
        elif fixed_value(pschema) != v:
            problem("%s: branch %s does not fix %s to %s" % (where, ref, prop, json.dumps(v)))
    if prop != "kind" or not kinds:
        return
    if sorted(mapping) != sorted(kinds):
        problem("%s: maps the kinds %s, x-kinds has %s" % (where, sorted(mapping), sorted(kinds)))
    for v, ref in mapping.items():
        k = kinds.get(v)
        try:
            node, _ = deref(spec, {"$ref": ref}, name)
        except KeyError:
            continue
        if not isinstance(k, dict):
            continue
        for key in ("params", "stats"):
            got, want = branch_ref(node, key), (k.get(key) or {}).get("$ref")
            if got is not None and got != want:
                problem("%s: branch %s has %s %s, x-kinds.%s.%s is %s"
                        % (where, ref, key, got, v, key, want))
        if branch_ref(node, "params") is None:
            problem("%s: branch %s does not $ref its params schema" % (where, ref))


def report_lint(problems, nops, nschemas=0):
    for p in problems:
        print("lint: %s" % p)
    if problems:
        print("openapi lint: %d problems" % len(problems))
        return 1
    print("openapi lint: OK (%d operations, %d schemas)" % (nops, nschemas))
    return 0


# --------------------------------------------------------------------------


def main(argv=None):
    ap = argparse.ArgumentParser(description="Check recorded voxeld responses against the OpenAPI spec.")
    ap.add_argument("spec", help="the OpenAPI 3.1 YAML file")
    ap.add_argument("log", nargs="?", help="LOG.jsonl of recorded responses")
    ap.add_argument("--require-all-paths", action="store_true",
                    help="fail when an operation of the spec was never exercised")
    ap.add_argument("--lint", action="store_true", help="check the spec itself and exit")
    args = ap.parse_args(argv)

    if args.lint:
        if args.log:
            ap.error("--lint takes no LOG")
        return lint(args.spec)
    if not args.log:
        ap.error("LOG.jsonl is required (or --lint)")
    try:
        spec = load_spec(args.spec)
    except (OSError, ValueError, yaml.YAMLError) as e:
        print("openapi: cannot load %s: %s" % (args.spec, e))
        return 2
    c = Checker(spec, args.log)
    try:
        c.run()
    except OSError as e:
        print("openapi: cannot read %s: %s" % (args.log, e))
        return 2
    ops = c.operations()
    if args.require_all_paths:
        for t, m in ops:
            if (t, m) not in c.exercised:
                c.fail("openapi", "operation %s %s was never exercised" % (m.upper(), t))
    if c.requests_skipped:
        print("openapi: note: %d request bodies over %d bytes were not checked"
              % (c.requests_skipped, MAX_REQUEST_CHECK_BYTES))
    if c.bodies_missing:
        print("openapi: note: %d body files were missing (bodies not checked)" % c.bodies_missing)
    print("openapi: %d responses checked, %d failures, %d/%d operations exercised"
          % (c.checked, c.failures, len(c.exercised & set(ops)), len(ops)))
    return 0 if c.failures == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
