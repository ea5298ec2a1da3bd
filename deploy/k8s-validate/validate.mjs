// Validates Kubernetes manifests offline against the API schema.
//
//   node validate.mjs FILE.yaml...
//
// Each document is checked twice, with models generated from Kubernetes'
// OpenAPI spec by two independent npm packages (versions pinned in
// package.json):
//   - kubernetes-models: JSON-schema validation of values (required fields,
//     types, int32/int64 and quantity formats);
//   - @kubernetes/client-node: every field name at every depth must exist in
//     the API type, so a typo (`contaners:`, `readinessProbe.grcp`) fails.
//     kubernetes-models alone accepts unknown fields, as the API server's
//     non-strict decoding would.
// Then the manifests are checked against each other: the ConfigMap keys,
// claims and services they name exist, and every Service selects a workload.
// A Kustomization (not an API kind) gets its own small strict check.
//
// Prints one line per document and a closing "N passed, N failed"; exits 1
// when anything failed.
import { readFileSync, existsSync } from "node:fs";
import path from "node:path";
import { parseAllDocuments } from "yaml";
import * as api from "@kubernetes/client-node/dist/gen/models/ObjectSerializer.js";

const kKustomizationFields = new Set([
  "apiVersion", "kind", "resources", "images", "namespace", "namePrefix", "nameSuffix",
  "labels", "commonLabels", "commonAnnotations", "patches", "configMapGenerator",
  "secretGenerator", "generatorOptions", "replicas", "components",
]);

function editDistance(a, b) {
  const d = Array.from({ length: a.length + 1 }, (_, i) => [i, ...Array(b.length).fill(0)]);
  for (let j = 1; j <= b.length; j++) d[0][j] = j;
  for (let i = 1; i <= a.length; i++) {
    for (let j = 1; j <= b.length; j++) {
      d[i][j] = Math.min(d[i - 1][j] + 1, d[i][j - 1] + 1,
                         d[i - 1][j - 1] + (a[i - 1] === b[j - 1] ? 0 : 1));
    }
  }
  return d[a.length][b.length];
}

function unknownField(key, known, where) {
  const best = [...known].sort((x, y) => editDistance(key, x) - editDistance(key, y))[0];
  const hint = best && editDistance(key, best) <= 3 ? ` (did you mean "${best}"?)` : "";
  return `${where}: unknown field "${key}"${hint}`;
}

const isPlainObject = (v) => v !== null && typeof v === "object" && !Array.isArray(v);

// Walks `value` as API type `type` (a client-node type name), collecting
// unknown fields and gross type mismatches in `errors`.
function checkFields(value, type, where, errors) {
  if (value === null || value === undefined) return;
  let m;
  if (type === "any" || type === "object") return;
  if (type === "string" || type === "Date") {
    if (typeof value !== "string") errors.push(`${where}: expected a string, got ${JSON.stringify(value)}`);
    return;
  }
  if (type === "number") {
    if (typeof value !== "number") errors.push(`${where}: expected a number, got ${JSON.stringify(value)}`);
    return;
  }
  if (type === "boolean") {
    if (typeof value !== "boolean") errors.push(`${where}: expected true or false, got ${JSON.stringify(value)}`);
    return;
  }
  if (type === "IntOrString") {
    if (typeof value !== "number" && typeof value !== "string") {
      errors.push(`${where}: expected a number or a string`);
    }
    return;
  }
  if ((m = /^Array<(.+)>$/.exec(type))) {
    if (!Array.isArray(value)) { errors.push(`${where}: expected a list`); return; }
    value.forEach((v, i) => checkFields(v, m[1], `${where}[${i}]`, errors));
    return;
  }
  if ((m = /^\{ \[key: string\]: (.+); \}$/.exec(type))) {
    if (!isPlainObject(value)) { errors.push(`${where}: expected a map`); return; }
    for (const [k, v] of Object.entries(value)) checkFields(v, m[1], `${where}.${k}`, errors);
    return;
  }
  const model = api[type];
  if (typeof model?.getAttributeTypeMap !== "function") {
    errors.push(`${where}: validator has no API type ${type}`);
    return;
  }
  if (!isPlainObject(value)) { errors.push(`${where}: expected an object (${type})`); return; }
  const fields = new Map(model.getAttributeTypeMap().map((a) => [a.baseName, a.type]));
  for (const [k, v] of Object.entries(value)) {
    if (!fields.has(k)) errors.push(unknownField(k, fields.keys(), where));
    else checkFields(v, fields.get(k), where === "" ? k : `${where}.${k}`, errors);
  }
}

async function checkSchema(doc, errors) {
  const [group, version] = doc.apiVersion.includes("/") ? doc.apiVersion.split("/") : ["", doc.apiVersion];
  const typeName = version[0].toUpperCase() + version.slice(1) + doc.kind;
  if (typeof api[typeName]?.getAttributeTypeMap !== "function") {
    errors.push(`no API type for apiVersion ${doc.apiVersion}, kind ${doc.kind}`);
    return;
  }
  checkFields(doc, typeName, "", errors);
  let model;
  try {
    model = (await import(`kubernetes-models/${group ? `${group}/` : ""}${version}/${doc.kind}`))[doc.kind];
  } catch {
    errors.push(`kubernetes-models has no ${doc.apiVersion} ${doc.kind}`);
    return;
  }
  try {
    new model(doc).validate();
  } catch (e) {
    for (const line of String(e.message).split(/\n|, (?=data)/)) errors.push(line.replace(/^data\/?/, "/"));
  }
}

function checkKustomization(doc, file, errors) {
  for (const k of Object.keys(doc)) {
    if (!kKustomizationFields.has(k)) errors.push(unknownField(k, kKustomizationFields, "kustomization"));
  }
  for (const r of doc.resources ?? []) {
    if (!existsSync(path.join(path.dirname(file), r))) errors.push(`resources: ${r} does not exist`);
  }
}

// Cross-references between the manifests (what the API server would only
// notice when a pod fails to start).
function checkReferences(docs) {
  const byKind = (kind) => docs.filter((d) => d.doc.kind === kind);
  const configMaps = new Map(byKind("ConfigMap").map((d) => [d.doc.metadata.name, d.doc.data ?? {}]));
  const claims = new Set(byKind("PersistentVolumeClaim").map((d) => d.doc.metadata.name));
  const services = new Map(byKind("Service").map((d) => [d.doc.metadata.name, d.doc]));
  const workloads = docs.filter((d) => ["Deployment", "StatefulSet", "DaemonSet"].includes(d.doc.kind));
  for (const w of workloads) {
    const spec = w.doc.spec?.template?.spec ?? {};
    const labels = w.doc.spec?.template?.metadata?.labels ?? {};
    for (const [k, v] of Object.entries(w.doc.spec?.selector?.matchLabels ?? {})) {
      if (labels[k] !== v) w.errors.push(`spec.selector.matchLabels.${k} does not match the pod template's labels`);
    }
    for (const c of [...(spec.containers ?? []), ...(spec.initContainers ?? [])]) {
      const ports = new Set((c.ports ?? []).flatMap((p) => [p.containerPort, p.name]));
      for (const e of c.env ?? []) {
        const ref = e.valueFrom?.configMapKeyRef;
        if (ref && !ref.optional) {
          if (!configMaps.has(ref.name)) w.errors.push(`container ${c.name}: env ${e.name}: no ConfigMap ${ref.name}`);
          else if (!(ref.key in configMaps.get(ref.name))) {
            w.errors.push(`container ${c.name}: env ${e.name}: ConfigMap ${ref.name} has no key ${ref.key}`);
          }
        }
      }
      for (const probe of ["livenessProbe", "readinessProbe", "startupProbe"]) {
        const port = c[probe]?.grpc?.port ?? c[probe]?.tcpSocket?.port ?? c[probe]?.httpGet?.port;
        if (port !== undefined && !ports.has(port)) {
          w.errors.push(`container ${c.name}: ${probe} port ${port} is not one of its ports`);
        }
      }
      const volumes = new Set((spec.volumes ?? []).map((v) => v.name));
      for (const m of c.volumeMounts ?? []) {
        if (!volumes.has(m.name)) w.errors.push(`container ${c.name}: volumeMount ${m.name} names no volume`);
      }
    }
    for (const v of spec.volumes ?? []) {
      const claim = v.persistentVolumeClaim?.claimName;
      if (claim && !claims.has(claim)) w.errors.push(`volume ${v.name}: no PersistentVolumeClaim ${claim}`);
    }
    if (w.doc.kind === "StatefulSet") {
      const svc = services.get(w.doc.spec.serviceName);
      if (!w.doc.spec.serviceName) w.errors.push("spec.serviceName is required");
      else if (!svc) w.errors.push(`spec.serviceName: no Service ${w.doc.spec.serviceName}`);
      else if (svc.spec?.clusterIP !== "None") w.errors.push(`Service ${svc.metadata.name} should be headless`);
    }
  }
  for (const s of byKind("Service")) {
    const sel = s.doc.spec?.selector ?? {};
    const match = workloads.find((w) => {
      const labels = w.doc.spec?.template?.metadata?.labels ?? {};
      return Object.entries(sel).every(([k, v]) => labels[k] === v);
    });
    if (!match) { s.errors.push("spec.selector matches no workload"); continue; }
    const ports = new Set((match.doc.spec.template.spec.containers ?? []).flatMap((c) => (c.ports ?? [])
      .flatMap((p) => [p.containerPort, p.name])));
    for (const p of s.doc.spec?.ports ?? []) {
      const target = p.targetPort ?? p.port;
      if (!ports.has(target)) s.errors.push(`port ${p.name ?? p.port}: targetPort ${target} is no port of ${match.doc.metadata.name}`);
    }
  }
  for (const b of byKind("PodDisruptionBudget")) {
    const sel = b.doc.spec?.selector?.matchLabels ?? {};
    const match = workloads.find((w) => {
      const labels = w.doc.spec?.template?.metadata?.labels ?? {};
      return Object.entries(sel).every(([k, v]) => labels[k] === v);
    });
    if (Object.keys(sel).length === 0 || !match) b.errors.push("spec.selector.matchLabels matches no workload");
  }
}

async function main(files) {
  if (files.length === 0) {
    console.error("usage: node validate.mjs FILE.yaml...");
    process.exit(2);
  }
  const docs = [];
  let failed = 0;
  for (const file of files) {
    const parsed = parseAllDocuments(readFileSync(file, "utf8"), { uniqueKeys: true, prettyErrors: true });
    for (const [i, d] of parsed.entries()) {
      const entry = { file, index: i, doc: null, errors: d.errors.map((e) => e.message) };
      if (entry.errors.length === 0) entry.doc = d.toJS();
      if (entry.doc === null && entry.errors.length === 0) continue;  // empty document
      docs.push(entry);
    }
  }
  for (const d of docs) {
    if (!d.doc) continue;
    if (!isPlainObject(d.doc) || typeof d.doc.apiVersion !== "string" || typeof d.doc.kind !== "string") {
      d.errors.push("not a Kubernetes object (apiVersion and kind are required)");
      d.doc = null;
      continue;
    }
    if (d.doc.kind === "Kustomization") { checkKustomization(d.doc, d.file, d.errors); continue; }
    if (!d.doc.metadata?.name) d.errors.push("metadata.name is required");
    if (d.doc.metadata?.namespace) d.errors.push("metadata.namespace: keep the manifests namespace-agnostic");
    await checkSchema(d.doc, d.errors);
  }
  checkReferences(docs.filter((d) => d.doc && d.doc.kind !== "Kustomization"));
  for (const d of docs) {
    const what = d.doc ? `${d.doc.kind}/${d.doc.metadata?.name ?? "?"}` : `document ${d.index + 1}`;
    if (d.errors.length === 0) {
      console.log(`ok    ${d.file}: ${what}`);
    } else {
      failed++;
      console.log(`FAIL  ${d.file}: ${what}`);
      for (const e of d.errors) console.log(`        ${e}`);
    }
  }
  console.log(`${docs.length - failed} passed, ${failed} failed`);
  process.exit(failed ? 1 : 0);
}

await main(process.argv.slice(2));
