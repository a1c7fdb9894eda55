// A form generated from a JSON Schema of api/openapi.yaml (a kind's params
// schema under x-kinds). Every field starts empty, meaning "left out": the
// daemon then applies the schema's default. Only fields the user set are
// sent. Scalars, enums and booleans get inputs; anything else (objects,
// arrays, oneOf/anyOf of several non-null types) a JSON text area.

// Resolves a local $ref ("#/components/schemas/X") against the document.
export function deref(doc, s) {
  let guard = 0;
  while (s && s.$ref && guard++ < 32) {
    const path = s.$ref.replace(/^#\//, '').split('/').map(p => p.replace(/~1/g, '/').replace(/~0/g, '~'));
    let t = doc;
    for (const p of path) t = t?.[p];
    s = t ? { ...t, ...Object.fromEntries(Object.entries(s).filter(([k]) => k !== '$ref')) } : null;
  }
  return s || {};
}

// The one non-null alternative of an anyOf/oneOf with null (or the schema).
function nonNull(doc, s) {
  const alts = s.anyOf || s.oneOf;
  if (!alts) return { schema: s, nullable: false };
  const rest = alts.map(a => deref(doc, a)).filter(a => a.type !== 'null');
  const nullable = rest.length < alts.length;
  if (rest.length === 1) return { schema: { ...rest[0], description: s.description || rest[0].description, default: s.default ?? rest[0].default }, nullable };
  return { schema: s, nullable, complex: true };
}

function el(tag, attrs = {}, ...kids) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null) continue;
    if (k === 'text') e.textContent = v; else e.setAttribute(k, v);
  }
  for (const k of kids) if (k) e.append(k);
  return e;
}

function firstLine(text) {
  if (!text) return '';
  // (Markdown's code spans shown as plain text)
  const t = String(text).trim().split(/\n\s*\n/)[0].replace(/\s+/g, ' ').replace(/`/g, '');
  return t.length > 240 ? t.slice(0, 237) + '...' : t;
}

// Builds the fields of schema into container; returns read(), which gives
// the params object or throws an Error naming the bad field.
export function buildForm(doc, schema, container) {
  schema = deref(doc, schema);
  const readers = [];
  const props = schema.properties || {};
  for (const [name, raw] of Object.entries(props)) {
    const s0 = deref(doc, raw);
    const { schema: s, complex } = nonNull(doc, s0);
    const type = Array.isArray(s.type) ? s.type.find(t => t !== 'null') : s.type;
    const def = s0.default ?? s.default;
    const hint = el('p', { class: 'hint', text: firstLine(s0.description || s.description) });
    const label = el('label', { text: name, for: `param-${name}` });
    const field = el('div', { class: 'field', 'data-field': name });
    let input, read;
    if (!complex && Array.isArray(s.enum)) {
      input = el('select', { name });
      input.append(el('option', { value: '', text: def !== undefined ? `(default: ${def})` : '(not set)' }));
      for (const v of s.enum) input.append(el('option', { value: JSON.stringify(v), text: String(v) }));
      read = () => (input.value === '' ? undefined : JSON.parse(input.value));
    } else if (!complex && type === 'boolean') {
      input = el('select', { name });
      input.append(el('option', { value: '', text: def !== undefined ? `(default: ${def})` : '(not set)' }));
      input.append(el('option', { value: 'true', text: 'true' }), el('option', { value: 'false', text: 'false' }));
      read = () => (input.value === '' ? undefined : input.value === 'true');
    } else if (!complex && (type === 'integer' || type === 'number')) {
      input = el('input', { name, type: 'number', step: type === 'integer' ? '1' : 'any',
        min: s.minimum, max: s.maximum, placeholder: def !== undefined ? `default ${def}` : '' });
      read = () => {
        if (input.value.trim() === '') return undefined;
        const v = Number(input.value);
        if (!Number.isFinite(v) || (type === 'integer' && !Number.isInteger(v))) throw new Error(`params.${name}: not a${type === 'integer' ? 'n integer' : ' number'}`);
        return v;
      };
    } else if (!complex && type === 'string') {
      input = el('input', { name, type: 'text', placeholder: def !== undefined ? `default ${def}` : '' });
      read = () => (input.value === '' ? undefined : input.value);
    } else {
      input = el('textarea', { name, rows: 2, placeholder: def !== undefined ? `JSON, default ${JSON.stringify(def)}` : 'JSON' });
      read = () => {
        if (input.value.trim() === '') return undefined;
        try { return JSON.parse(input.value); } catch (e) { throw new Error(`params.${name}: not JSON (${e.message})`); }
      };
    }
    input.id = `param-${name}`;
    field.append(label, input, hint);
    container.append(field);
    readers.push([name, read]);
  }
  return () => {
    const out = {};
    for (const [name, read] of readers) {
      const v = read();
      if (v !== undefined) out[name] = v;
    }
    return out;
  };
}
