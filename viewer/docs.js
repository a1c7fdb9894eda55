// The API reference at /docs: api/openapi.yaml (served at /openapi.yaml)
// rendered in the browser: the description, every operation with its
// parameters and answers, and every schema.
const doc = document.getElementById('doc');

const esc = s => String(s ?? '').replace(/[&<>"]/g, c => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;' }[c]));

// Inline Markdown: `code`, **bold**, *em*, [text](url).
function inline(s) {
  return esc(s)
    .replace(/`([^`]+)`/g, '<code>$1</code>')
    .replace(/\*\*([^*]+)\*\*/g, '<b>$1</b>')
    .replace(/(^|[\s(])\*([^*\s][^*]*)\*/g, '$1<i>$2</i>')
    .replace(/\[([^\]]+)\]\(([^)\s]+)\)/g, (m, t, u) => (/^(https?:|#|\/)/.test(u) ? `<a href="${u}">${t}</a>` : m));
}

// Block Markdown, the subset the contract uses: headings, paragraphs,
// lists, tables and fenced code.
function markdown(text) {
  const lines = String(text ?? '').split('\n'), out = [];
  for (let i = 0; i < lines.length;) {
    const l = lines[i];
    if (/^```/.test(l)) {
      const code = [];
      for (i++; i < lines.length && !/^```/.test(lines[i]); i++) code.push(lines[i]);
      i++;
      out.push(`<pre>${esc(code.join('\n'))}</pre>`);
    } else if (/^#{1,6} /.test(l)) {
      const n = l.match(/^#+/)[0].length;
      out.push(`<h${n + 2}>${inline(l.slice(n + 1))}</h${n + 2}>`);
      i++;
    } else if (/^\s*\|/.test(l)) {
      const rows = [];
      for (; i < lines.length && /^\s*\|/.test(lines[i]); i++) rows.push(lines[i].trim().replace(/^\||\|$/g, '').split('|'));
      const body = rows.filter((r, k) => !(k === 1 && r.every(c => /^\s*:?-+:?\s*$/.test(c))));
      out.push('<table>' + body.map((r, k) => `<tr>${r.map(c => (k ? `<td>${inline(c.trim())}</td>` : `<th>${inline(c.trim())}</th>`)).join('')}</tr>`).join('') + '</table>');
    } else if (/^\s*[*-] /.test(l)) {
      const items = [];
      for (; i < lines.length && (/^\s*[*-] /.test(lines[i]) || (/^\s{2,}\S/.test(lines[i]) && items.length)); i++) {
        if (/^\s*[*-] /.test(lines[i])) items.push(lines[i].replace(/^\s*[*-] /, ''));
        else items[items.length - 1] += ' ' + lines[i].trim();
      }
      out.push('<ul>' + items.map(t => `<li>${inline(t)}</li>`).join('') + '</ul>');
    } else if (!l.trim()) {
      i++;
    } else {
      const para = [];
      for (; i < lines.length && lines[i].trim() && !/^(```|#{1,6} |\s*\||\s*[*-] )/.test(lines[i]); i++) para.push(lines[i].trim());
      out.push(`<p>${inline(para.join(' '))}</p>`);
    }
  }
  return out.join('\n');
}

const refName = r => r.replace(/^#\/components\/[^/]+\//, '');
const schemaLink = s => (s?.$ref ? `<a href="#schema-${esc(refName(s.$ref))}">${esc(refName(s.$ref))}</a>` : '');

function operation(spec, path, method, op, shared) {
  const params = [...(shared || []), ...(op.parameters || [])].map(p => (p.$ref ? { ...deref(spec, p), ref: p.$ref } : p));
  let h = `<div class="op" id="op-${esc(op.operationId || method + path)}"><h3><span class="method">${esc(method)}</span> <code>${esc(path)}</code> ${inline(op.summary || '')}</h3>`;
  if (op.security && !op.security.length) h += '<p><i>No token needed.</i></p>';
  h += markdown(op.description);
  if (params.length) {
    h += '<h4>Parameters</h4><table><tr><th>name</th><th>in</th><th>required</th><th>description</th></tr>';
    for (const p of params) h += `<tr><td><code>${esc(p.name)}</code></td><td>${esc(p.in)}</td><td>${p.required ? 'yes' : ''}</td><td>${inline(p.description || '')}</td></tr>`;
    h += '</table>';
  }
  const rb = op.requestBody && deref(spec, op.requestBody);
  if (rb) {
    h += '<h4>Request body</h4>' + markdown(rb.description);
    h += '<ul>' + Object.entries(rb.content || {}).map(([t, c]) => `<li><code>${esc(t)}</code> ${schemaLink(c.schema)}</li>`).join('') + '</ul>';
  }
  h += '<h4>Responses</h4><table>';
  for (const [code, r0] of Object.entries(op.responses || {})) {
    const r = deref(spec, r0);
    const types = Object.entries(r.content || {}).map(([t, c]) => `<code>${esc(t)}</code> ${schemaLink(c.schema)}`).join(', ');
    h += `<tr><td><b>${esc(code)}</b></td><td>${inline(String(r.description || '').split(/\n\s*\n/)[0])}</td><td>${types}</td></tr>`;
  }
  return h + '</table></div>';
}

function deref(spec, o) {
  for (let n = 0; o && o.$ref && n < 16; n++) o = o.$ref.replace(/^#\//, '').split('/').reduce((t, k) => t?.[k], spec);
  return o || {};
}

async function main() {
  let spec;
  try {
    const { load, dump } = await import('/ui/js-yaml.mjs');
    spec = load(await (await fetch('/openapi.yaml')).text());
    window.yamlDump = dump;
  } catch (e) {
    doc.innerHTML = `<p>Cannot render the reference here (${esc(e.message)}); read <a href="/openapi.yaml">/openapi.yaml</a>.</p>`;
    return;
  }
  let h = `<h2>${esc(spec.info?.title)} ${esc(spec.info?.version)}</h2>` + markdown(spec.info?.description);
  h += '<h2>Operations</h2><ul>';
  const ops = [];
  for (const [path, item] of Object.entries(spec.paths || {}))
    for (const m of ['get', 'put', 'post', 'delete', 'patch', 'head', 'options'])
      if (item[m]) ops.push([path, m, item[m], item.parameters]);
  for (const [path, m, op] of ops) h += `<li><a href="#op-${esc(op.operationId || m + path)}"><span class="method">${m}</span> ${esc(path)}</a> ${inline(op.summary || '')}</li>`;
  h += '</ul>';
  for (const [path, m, op, shared] of ops) h += operation(spec, path, m, op, shared);
  h += '<h2>Job kinds</h2><table><tr><th>kind</th><th>params</th><th>stats</th><th>outputs</th><th></th></tr>';
  for (const [k, d] of Object.entries(spec['x-kinds'] || {})) {
    const outs = (d.outputs || []).map(o => `<code>${esc(o.name)}</code>`).join(', ');
    h += `<tr><td><code>${esc(k)}</code></td><td>${schemaLink(d.params)}</td><td>${schemaLink(d.stats)}</td><td>${outs}</td><td>${inline(d.summary || '')}</td></tr>`;
  }
  h += '</table><h2>Schemas</h2>';
  for (const [name, s] of Object.entries(spec.components?.schemas || {})) {
    h += `<div class="op" id="schema-${esc(name)}"><h3>${esc(name)}</h3>${markdown(s.description)}`;
    h += `<details><summary>schema</summary><pre>${esc(window.yamlDump(s, { lineWidth: 100 }))}</pre></details></div>`;
  }
  doc.innerHTML = h;
  document.body.dataset.ready = '1';
}

main();
