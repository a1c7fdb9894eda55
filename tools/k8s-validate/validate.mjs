// Validates rendered Kubernetes manifests (multi-document YAML, e.g. the
// output of `kubectl kustomize`) against the Kubernetes API schemas
// (kubernetes-models) and KEDA's (@kubernetes-models/keda), offline.
//
//   node validate.mjs [--json OUT] FILE...
//
// Prints one line per object; exits 1 when an object is invalid, has an
// apiVersion/kind neither package knows, or a file is not YAML. --json writes
// every object as one JSON array (for assertions with jq). The schemas check
// types, required fields, enums and formats; like the API server without
// strict field validation, they do not reject unknown fields.
import { readFileSync, writeFileSync } from "node:fs";
import { parseAllDocuments } from "yaml";

// The module of an apiVersion/kind: core "v1" objects live at
// kubernetes-models/v1/KIND, grouped ones at kubernetes-models/GROUP/VERSION/KIND,
// KEDA's under @kubernetes-models/keda.
function modulePath(apiVersion, kind) {
  if (typeof apiVersion !== "string" || typeof kind !== "string" || !/^[A-Za-z0-9]+$/.test(kind))
    return null;
  const slash = apiVersion.indexOf("/");
  const group = slash < 0 ? "" : apiVersion.slice(0, slash);
  if (group === "keda.sh") return `@kubernetes-models/keda/${apiVersion}/${kind}`;
  return `kubernetes-models/${apiVersion}/${kind}`;
}

async function check(obj) {
  const path = modulePath(obj?.apiVersion, obj?.kind);
  if (!path) return "no apiVersion/kind";
  let mod;
  try {
    mod = await import(path);
  } catch {
    return `unknown apiVersion/kind ${obj.apiVersion} ${obj.kind}`;
  }
  const Model = mod[obj.kind];
  if (typeof Model !== "function") return `unknown kind ${obj.kind} in ${obj.apiVersion}`;
  // kustomize wraps long base64 Secret values over lines; the API server's
  // decoder (Go's encoding/base64) skips the newlines, the schema's "byte"
  // format does not: check the value without them.
  let subject = obj;
  if (obj.apiVersion === "v1" && obj.kind === "Secret" && obj.data && typeof obj.data === "object") {
    const data = {};
    for (const [k, v] of Object.entries(obj.data))
      data[k] = typeof v === "string" ? v.replace(/[\r\n]/g, "") : v;
    subject = { ...obj, data };
  }
  try {
    new Model(subject).validate();
  } catch (e) {
    return e.message;
  }
  if (!obj.metadata?.name) return "metadata.name is missing";
  return null;
}

const args = process.argv.slice(2);
let jsonOut = null;
if (args[0] === "--json") {
  jsonOut = args[1];
  args.splice(0, 2);
}
if (!args.length) {
  console.error("usage: node validate.mjs [--json OUT] FILE...");
  process.exit(2);
}
let bad = 0;
const all = [];
for (const file of args) {
  const docs = parseAllDocuments(readFileSync(file, "utf8"));
  for (const doc of docs) {
    if (doc.errors.length) {
      console.log(`INVALID ${file}: ${doc.errors[0].message}`);
      bad++;
      continue;
    }
    const obj = doc.toJS();
    if (obj === null) continue;
    all.push(obj);
    const err = await check(obj);
    const name = `${obj?.kind}/${obj?.metadata?.name}`;
    if (err) {
      console.log(`INVALID ${file}: ${name}: ${err}`);
      bad++;
    } else {
      console.log(`ok ${obj.apiVersion} ${name}`);
    }
  }
}
if (jsonOut) writeFileSync(jsonOut, JSON.stringify(all, null, 1));
process.exit(bad ? 1 : 0);
