// The voxeld viewer (README "Viewer"). Served by the daemon at / from files
// built into it; talks to the API on the same origin. The page itself is
// public; with --token the API calls carry the token entered at the top
// (kept in this browser's localStorage).
import { buildForm, deref } from '/ui/forms.js';

const $ = id => document.getElementById(id);
const TERMINAL = new Set(['succeeded', 'failed', 'canceled']);
const TOKEN_KEY = 'voxeld.token';
let spec = null, view = null, viewLib = null, readParams = null;
let current = null; // the job shown: {id, follow: a number bumped to stop following}
let followSeq = 0;

// ---- the API -------------------------------------------------------------

class ApiError extends Error {
  constructor(status, body) {
    super(body?.error ? `${status} ${body.error.code}: ${body.error.message}` : `HTTP ${status}`);
    this.status = status;
    this.body = body;
  }
}

function authHeaders(extra = {}) {
  const h = new Headers(extra);
  const t = localStorage.getItem(TOKEN_KEY) || '';
  if (t) h.set('Authorization', `Bearer ${t}`);
  return h;
}

export async function api(path, opts = {}) {
  return fetch(path, { ...opts, headers: authHeaders(opts.headers || {}) });
}

// res when it is a success, else throws its ApiError (with the JSON error
// body where there is one).
async function checked(res) {
  if (res.ok) return res;
  let body = null;
  try { body = await res.json(); } catch { /* not JSON */ }
  throw new ApiError(res.status, body);
}

async function apiJSON(path, opts) {
  const res = await api(path, opts);
  let body = null;
  try { body = await res.json(); } catch { /* not JSON */ }
  if (!res.ok) throw new ApiError(res.status, body);
  return body;
}

// A list, newest first whatever the server's order: ?order=desc is asked
// for; a server that lists by id instead (meshes; jobs on servers without
// order) is read to its end (at most `pages` of 1000) and sorted here.
async function listAll(path, pages = 10) {
  let items = [], after = null;
  for (let i = 0; i < pages; i++) {
    const q = `limit=1000&order=desc${after ? `&after=${encodeURIComponent(after)}` : ''}`;
    const page = await apiJSON(`${path}?${q}`);
    items = items.concat(page.items);
    const n = page.items.length;
    const newestFirst = n > 1 && page.items[0].created > page.items[n - 1].created;
    if (!page.next || (newestFirst && path === '/v1/jobs')) break;
    after = page.next;
  }
  return items.sort((a, b) => (a.created < b.created ? 1 : a.created > b.created ? -1 : 0));
}

function notice(text) {
  const n = $('notice');
  n.hidden = !text;
  n.textContent = text || '';
}

function showError(e, where) {
  const msg = e instanceof ApiError && e.status === 401
    ? ($('token').value.trim() ? 'The server refused this bearer token: check the one at the top.'
      : 'The server wants a bearer token: enter it at the top.')
    : String(e.message || e);
  (where ? $(where) : $('notice')).textContent = msg;
  if (!where) $('notice').hidden = false;
}

// ---- lists ------------------------------------------------------------------

const short = id => id.slice(0, 12);
const when = ts => (ts ? ts.replace('T', ' ').replace(/\.\d+Z$/, 'Z') : '');

// A list item or zone that acts on a click acts on Enter and Space too, and
// takes the focus in turn.
function keyboard(node, act = () => node.onclick()) {
  node.tabIndex = 0;
  if (!node.getAttribute('role')) node.setAttribute('role', 'button');
  node.onkeydown = e => {
    if (e.key !== 'Enter' && e.key !== ' ') return;
    e.preventDefault();
    act();
  };
}

// The meshes list marks the mesh the form's menu has chosen.
function markMesh() {
  for (const li of $('meshes').children) {
    const on = li.dataset.id === $('mesh').value;
    li.classList.toggle('sel', on);
    li.setAttribute('aria-pressed', on ? 'true' : 'false');
  }
}

async function refreshMeshes() {
  const meshes = await listAll('/v1/meshes');
  const ul = $('meshes'), sel = $('mesh'), keep = sel.value;
  const focused = ul.contains(document.activeElement) ? document.activeElement.dataset.id : null;
  ul.replaceChildren();
  sel.replaceChildren();
  for (const m of meshes) {
    const label = m.name || short(m.id);
    const li = document.createElement('li');
    li.dataset.id = m.id;
    li.innerHTML = `<b></b> <span class="id"></span><br><small></small>`;
    li.querySelector('b').textContent = label;
    li.querySelector('.id').textContent = m.name ? short(m.id) : '';
    li.querySelector('small').textContent = `${m.format}, ${m.triangles} triangles, ${when(m.created)}`;
    li.onclick = () => { sel.value = m.id; markMesh(); };
    keyboard(li);
    ul.append(li);
    if (m.id === focused) li.focus();
    const o = document.createElement('option');
    o.value = m.id;
    o.textContent = `${label} (${m.triangles} tris)`;
    sel.append(o);
  }
  if (keep && meshes.some(m => m.id === keep)) sel.value = keep;
  sel.onchange = markMesh;
  markMesh();
  return meshes;
}

async function refreshJobs() {
  const jobs = (await listAll('/v1/jobs', 10)).slice(0, 200);
  const ul = $('jobs');
  // the item with the keyboard's focus keeps it (the list is rebuilt at
  // every change of state: the focus went back to the page's start)
  const focused = ul.contains(document.activeElement) ? document.activeElement.dataset.id : null;
  ul.replaceChildren();
  for (const j of jobs) {
    const li = document.createElement('li');
    li.dataset.id = j.id;
    if (current?.id === j.id) li.classList.add('sel');
    li.innerHTML = `<b></b> <span></span> <span class="id"></span><br><small></small>`;
    li.querySelector('b').textContent = j.kind;
    const st = li.querySelector('span');
    st.textContent = j.state === 'running' ? `running ${Math.round(100 * j.progress)}%` : j.state;
    st.className = `state-${j.state}`;
    li.querySelector('.id').textContent = short(j.id);
    li.querySelector('small').textContent = `on ${short(j.mesh)}, ${when(j.created)}`;
    li.onclick = () => openJob(j.id);
    keyboard(li);
    ul.append(li);
    if (j.id === focused) li.focus();
  }
}

async function refreshAll() {
  try {
    await Promise.all([refreshMeshes(), refreshJobs()]);
    if (!$('notice').dataset.sticky) notice('');
  } catch (e) { showError(e); }
}

// ---- upload -----------------------------------------------------------------

const MEDIA = { obj: 'model/obj', drc: 'model/x-draco', bpt: 'model/x-bpt' };

// The file's name as a mesh name the server takes (1 to 100 bytes of
// UTF-8, no control or invisible format characters (the spec's list:
// U+061C, U+200B-200F, U+202A-202E, U+2060-206F, U+FEFF), '/', '\\' or
// '"', not "." or ".."):
// those characters become '_', a longer name keeps its end (the
// extension); '' when nothing is left.
function meshName(name) {
  let n = name.replace(/[\u0000-\u001f\u007f-\u009f\/\\"\u061c\u200b-\u200f\u202a-\u202e\u2060-\u206f\ufeff]/g, '_');
  const enc = new TextEncoder();
  while (enc.encode(n).length > 100) n = Array.from(n).slice(1).join('');
  return n === '.' || n === '..' ? '' : n;
}

async function upload(file) {
  const ext = (file.name.split('.').pop() || '').toLowerCase();
  // Formats the daemon does not name by type are sent for sniffing.
  const type = MEDIA[ext] || 'application/octet-stream';
  $('upload-status').textContent = `uploading ${file.name} (${file.size} bytes)...`;
  try {
    const name = meshName(file.name);
    const m = await apiJSON(name ? `/v1/meshes?name=${encodeURIComponent(name)}` : '/v1/meshes',
      { method: 'POST', headers: { 'Content-Type': type }, body: file });
    await refreshMeshes();
    $('mesh').value = m.id;
    // Said once the list shows the mesh (the browser test waits for it).
    $('upload-status').textContent = `${file.name}: mesh ${short(m.id)}, ${m.triangles} triangles`;
  } catch (e) { showError(e, 'upload-status'); }
}

// A file dropped anywhere on the page is uploaded (and the browser does not
// open it instead); the drop zone lights up while one is dragged over.
function setupDrop() {
  const drop = $('drop');
  document.addEventListener('dragover', e => { e.preventDefault(); drop.classList.add('over'); });
  document.addEventListener('dragleave', e => { if (!e.relatedTarget) drop.classList.remove('over'); });
  document.addEventListener('drop', e => {
    e.preventDefault();
    drop.classList.remove('over');
    for (const f of e.dataTransfer?.files || []) upload(f);
  });
  $('file').addEventListener('change', e => { for (const f of e.target.files) upload(f); e.target.value = ''; });
  keyboard(drop, () => $('file').click());
}

// ---- the job form -----------------------------------------------------------

function setupForm() {
  const kinds = spec['x-kinds'] || {};
  const sel = $('kind');
  for (const k of Object.keys(kinds)) {
    const o = document.createElement('option');
    o.value = o.textContent = k;
    sel.append(o);
  }
  const build = () => {
    const k = kinds[sel.value];
    const fs = $('params');
    fs.replaceChildren(Object.assign(document.createElement('legend'), { textContent: `params (${deref(spec, k.params).title || sel.value})` }));
    $('kind-summary').textContent = k.summary || '';
    readParams = buildForm(spec, k.params, fs);
  };
  sel.onchange = build;
  build();
  $('job-form').onsubmit = async e => {
    e.preventDefault();
    $('submit-status').textContent = '';
    let params;
    try { params = readParams(); } catch (err) { $('submit-status').textContent = err.message; return; }
    if (!$('mesh').value) { $('submit-status').textContent = 'upload a mesh first'; return; }
    try {
      const job = await apiJSON('/v1/jobs', { method: 'POST', headers: { 'Content-Type': 'application/json' },
        body: JSON.stringify({ mesh: $('mesh').value, kind: sel.value, params }) });
      $('submit-status').textContent = `job ${short(job.id)} submitted`;
      openJob(job.id, job);
      refreshJobs().catch(() => {});
    } catch (err) { showError(err, 'submit-status'); }
  };
}

// ---- following a job: Server-Sent Events, else polling ----------------------

// Reads GET /v1/jobs/{id}/events (text/event-stream: "event: job" +
// "data: <Job JSON>" per change) through fetch, which, unlike EventSource,
// can send the bearer token and see a 404. Returns false when the server
// has no events route (then the caller polls), true when the stream ended.
async function followEvents(jid, seq, onJob) {
  let res;
  try {
    res = await api(`/v1/jobs/${jid}/events`, { headers: { Accept: 'text/event-stream' } });
  } catch { return false; }
  if (!res.ok || !(res.headers.get('Content-Type') || '').startsWith('text/event-stream')) return false;
  const reader = res.body.getReader(), dec = new TextDecoder();
  let buf = '', terminal = false;
  for (;;) {
    const { value, done } = await reader.read();
    if (done || seq !== followSeq) break;
    buf += dec.decode(value, { stream: true }).replace(/\r\n?/g, '\n');
    let cut;
    while ((cut = buf.indexOf('\n\n')) >= 0) {
      const block = buf.slice(0, cut);
      buf = buf.slice(cut + 2);
      let event = 'message', data = [];
      for (const l of block.split('\n')) {
        if (l.startsWith(':')) continue;
        const [k, ...rest] = l.split(':');
        const v = rest.join(':').replace(/^ /, '');
        if (k === 'event') event = v; else if (k === 'data') data.push(v);
      }
      if (event === 'job' && data.length) {
        const job = JSON.parse(data.join('\n'));
        onJob(job);
        terminal = TERMINAL.has(job.state);
      }
    }
  }
  reader.cancel().catch(() => {});
  return terminal || seq !== followSeq;
}

// Polls with ?wait=1; while the server holds as many waits as it allows
// (503 too_many_waits) it is asked without one, a second apart. A server
// that answers ?wait at once (--request-timeout 0) is asked once a second,
// not as fast as it answers.
async function followPoll(jid, seq, onJob) {
  while (seq === followSeq) {
    let job;
    const t0 = performance.now();
    try {
      job = await apiJSON(`/v1/jobs/${jid}?wait=1`);
    } catch (e) {
      if (!(e instanceof ApiError && e.body?.error?.code === 'too_many_waits')) throw e;
      await new Promise(r => setTimeout(r, 1000));
      job = await apiJSON(`/v1/jobs/${jid}`);
    }
    onJob(job);
    if (TERMINAL.has(job.state)) return;
    const left = 1000 - (performance.now() - t0);
    if (left > 0) await new Promise(r => setTimeout(r, left));
  }
}

async function openJob(jid, first) {
  const seq = ++followSeq;
  current = { id: jid };
  // in the address (#job=ID): a reload, or Back from /docs, shows it again
  if (location.hash !== `#job=${jid}`) history.replaceState(null, '', `#job=${jid}`);
  for (const li of $('jobs').children) li.classList.toggle('sel', li.dataset.id === jid);
  clearResult();
  $('job-title').textContent = short(jid);
  let shown = null;
  let lastState = null;
  const onJob = job => {
    if (seq !== followSeq) return;
    showState(job);
    // the list says what the panel says (it showed queued while running)
    if (lastState !== null && job.state !== lastState && !TERMINAL.has(job.state)) refreshJobs().catch(() => {});
    lastState = job.state;
    if (TERMINAL.has(job.state) && shown !== job.state) {
      shown = job.state;
      showResult(job, seq).catch(e => showError(e, 'view-note'));
      refreshJobs().catch(() => {});
    }
  };
  // A server that stops answering (restarted, the network gone) is tried
  // again, 1, 2, 4 ... 10 s apart, while this job is the one shown.
  for (let wait = 1; seq === followSeq; wait = Math.min(2 * wait, 10)) {
    try {
      onJob(first || await apiJSON(`/v1/jobs/${jid}`));
      first = null;
      if (shown) return;
      if (!(await followEvents(jid, seq, onJob))) await followPoll(jid, seq, onJob);
      else if (!shown && seq === followSeq) await followPoll(jid, seq, onJob); // the stream broke off
      return;
    } catch (e) {
      if (e instanceof ApiError && e.status !== 503) { showError(e, 'job-error'); return; }
      if (seq !== followSeq) return;
      $('job-error').textContent = `the server is not answering (${e.message}); trying again in ${wait} s`;
      await new Promise(r => setTimeout(r, wait * 1000));
    }
  }
}

// Cancels the job shown (DELETE on a queued or running job): its stream
// then tells it canceled.
async function cancelJob() {
  if (!current) return;
  try {
    const res = await api(`/v1/jobs/${current.id}`, { method: 'DELETE' });
    if (res.status !== 404) await checked(res); // 404: it ended and went meanwhile
  } catch (e) { showError(e, 'job-error'); }
}

function showState(job) {
  $('progress').value = job.progress;
  $('cancel').hidden = TERMINAL.has(job.state);
  const pct = `${Math.round(100 * job.progress)}%`;
  $('state').textContent = `${job.kind} on ${short(job.mesh)}: ${job.state}${job.state === 'running' ? ` ${pct}` : ''}`;
  $('state').className = `state-${job.state}`;
  $('job-error').textContent = job.error && job.state !== 'succeeded' ? `${job.error.code}: ${job.error.message || ''}` : '';
  $('job-json').textContent = JSON.stringify(job, null, 2);
  document.body.dataset.jobState = job.state; // for scripts driving the page
}

// ---- results -------------------------------------------------------------------

let turntable = null;
const blobUrls = [];

function clearResult() {
  if (turntable) clearInterval(turntable);
  turntable = null;
  while (blobUrls.length) URL.revokeObjectURL(blobUrls.pop());
  $('images').replaceChildren();
  $('outputs').replaceChildren();
  $('view-note').textContent = '';
  $('job-error').textContent = '';
  $('view-wrap').hidden = true;
  delete document.body.dataset.resultShown;
  view?.clear();
}

async function fetchOutput(url, as) {
  const res = await checked(await api(url));
  return as === 'text' ? res.text() : as === 'blob' ? res.blob() : res.arrayBuffer();
}

// The file name a Content-Disposition answer gives: filename* (RFC 8187,
// UTF-8) first, else filename; '' when there is none.
function dispositionName(cd) {
  if (!cd) return '';
  const star = /filename\*\s*=\s*UTF-8''([^;]+)/i.exec(cd);
  if (star) { try { return decodeURIComponent(star[1].trim()); } catch { /* fall back */ } }
  const plain = /filename\s*=\s*"([^"]*)"/i.exec(cd) || /filename\s*=\s*([^;\s]+)/i.exec(cd);
  return plain ? plain[1] : '';
}

function listOutputs(job) {
  for (const [name, url] of Object.entries(job.outputs || {})) {
    const li = document.createElement('li'), a = document.createElement('a');
    a.textContent = name;
    a.href = '#';
    a.onclick = async e => {
      e.preventDefault();
      try {
        const res = await checked(await api(url));
        const u = URL.createObjectURL(await res.blob());
        const file = dispositionName(res.headers.get('Content-Disposition')) || `${short(job.id)}-${name}`;
        const d = Object.assign(document.createElement('a'), { href: u, download: file });
        d.click();
        setTimeout(() => URL.revokeObjectURL(u), 10000);
      } catch (err) { showError(err, 'job-error'); }
    };
    li.append(a);
    $('outputs').append(li);
  }
}

async function get3D() {
  if (view) return view;
  try {
    viewLib = await import('/ui/view3d.js');
  } catch (e) {
    throw new Error(`the 3D view is not available in this build (${e.message}): build voxeld after npm ci --prefix tools/viewer`);
  }
  view = new viewLib.View3D($('view3d'));
  return view;
}

async function showImages(job, seq) {
  const names = Object.keys(job.outputs).filter(n => /^image(_\d+)?$/.test(n)).sort();
  const urls = [];
  for (const n of names) {
    const blob = await fetchOutput(job.outputs[n], 'blob');
    if (seq !== followSeq) return; // another job was opened meanwhile
    const u = URL.createObjectURL(blob);
    blobUrls.push(u);
    urls.push(u);
  }
  if (!urls.length) return;
  const img = document.createElement('img');
  img.src = urls[0];
  img.alt = `${job.kind} ${names[0]}`;
  $('images').append(img);
  if (urls.length > 1) { // a turntable: play the frames
    let f = 0;
    img.title = `turntable, ${urls.length} frames`;
    turntable = setInterval(() => { f = (f + 1) % urls.length; img.src = urls[f]; }, 1000 / 12);
  }
  document.body.dataset.resultShown = 'image';
}

// A voxelize job's params as one binvox job: bricks, merge and the vdb-only
// fields are refused with a dense format (422).
function binvoxParams(params) {
  const { bricks, merge, vdb_grid, vdb_index_base, ...rest } = params;
  return { ...rest, format: 'binvox' };
}

async function showMesh(job, seq) {
  const fmt = job.params?.format || 'obj';
  if (fmt !== 'obj' && fmt !== 'ply') { // drc, glb: download only
    $('view-note').textContent = `${fmt === 'drc' ? 'Draco' : fmt} output: download it below (the 3D view reads OBJ and PLY).`;
    return;
  }
  const v = await get3D();
  if (seq !== followSeq) return;
  $('view-wrap').hidden = false;
  v.resize();
  // the job's mesh first, then its frames in order (frame_001, frame_002...)
  const names = ['mesh', ...Object.keys(job.outputs).filter(n => /^frame_\d+$/.test(n)).sort()];
  const as = fmt === 'ply' ? 'buffer' : 'text';
  const data = await fetchOutput(job.outputs.mesh, as);
  if (seq !== followSeq) return;
  const tris = v.showMesh(data, fmt);
  $('view-note').textContent = `${job.kind}: ${tris} triangles; drag to orbit, wheel to zoom`;
  document.body.dataset.resultShown = 'mesh';
  if (names.length > 1) {
    // every frame (the spec allows 256) while they hold at most 16M
    // triangles in all, the job's mesh with them
    const fit = Math.min(names.length, Math.floor(16e6 / Math.max(tris, 1)));
    if (fit < names.length)
      $('view-note').textContent += fit < 2 ? `; ${names.length - 1} frames not played (16M triangles in all)`
        : `; the first ${fit - 1} of ${names.length - 1} frames played (16M triangles in all)`;
    if (fit >= 2) await playFrames(job, names.slice(0, fit), fmt, as, v);
  }
}

// Deformation frames (gregory's frame_001, ...): loaded, then played in
// turn with the camera kept; a button stops and starts them.
async function playFrames(job, names, fmt, as, v) {
  const seq = followSeq, objects = [v.object];
  for (const n of names.slice(1)) {
    const data = await fetchOutput(job.outputs[n], as);
    if (seq !== followSeq) return;
    objects.push(v.parseMesh(data, fmt));
  }
  let f = 0;
  const step = () => { f = (f + 1) % objects.length; v.swap(objects[f]); };
  const button = Object.assign(document.createElement('button'), { type: 'button', textContent: `pause (${objects.length} frames)` });
  button.onclick = () => {
    if (turntable) { clearInterval(turntable); turntable = null; button.textContent = `play (${objects.length} frames)`; }
    else { turntable = setInterval(step, 1000 / 8); button.textContent = `pause (${objects.length} frames)`; }
  };
  $('images').append(button);
  turntable = setInterval(step, 1000 / 8);
}

async function showVoxels(job, seq) {
  const fmt = job.params?.format || 'vdb';
  if (!['binvox', 'raw8', 'raw1'].includes(fmt)) {
    $('view-note').textContent = fmt === 'summary' ? 'format summary: no voxels, only the stats.'
      : `format ${fmt}: the 3D view reads binvox, raw8 and raw1.`;
    if (fmt !== 'summary') { // the same job as binvox (its normalised params are valid input)
      const again = Object.assign(document.createElement('button'), { type: 'button', textContent: 'run it again as binvox to see it' });
      again.onclick = async () => {
        try {
          const j = await apiJSON('/v1/jobs', { method: 'POST', headers: { 'Content-Type': 'application/json' },
            body: JSON.stringify({ mesh: job.mesh, kind: job.kind, params: binvoxParams(job.params) }) });
          openJob(j.id, j);
          refreshJobs().catch(() => {});
        } catch (e) { showError(e, 'view-note'); }
      };
      $('images').append(again);
    }
    return;
  }
  const v = await get3D();
  const buf = await fetchOutput(job.outputs.voxels, 'buffer');
  if (seq !== followSeq) return; // another job was opened meanwhile
  $('view-wrap').hidden = false;
  v.resize();
  const grid = fmt === 'binvox' ? viewLib.parseBinvox(buf) : viewLib.parseRaw(buf, fmt === 'raw1', job.stats);
  const r = v.showVoxels(grid);
  $('view-note').textContent = `voxels ${grid.dims.join(' x ')}: ${r.inside} inside, ${r.surface} on the surface, ${r.drawn} cubes drawn`;
  document.body.dataset.resultShown = 'voxels';
}

async function showResult(job, seq) {
  clearResult();
  $('job-title').textContent = short(job.id);
  showState(job);
  listOutputs(job);
  if (job.state !== 'succeeded' || seq !== followSeq) return;
  if (job.kind === 'voxelize') await showVoxels(job, seq);
  else if (job.kind === 'gregory' || job.kind === 'catmull-clark') await showMesh(job, seq);
  else await showImages(job, seq);
}

// ---- start ---------------------------------------------------------------------

// The server's version at the top (again once a token is entered: without
// it /v1/info is 401).
async function showVersion() {
  try {
    const info = await (await fetch('/v1/info', { headers: authHeaders() })).json();
    if (info.version) $('server-info').textContent = `v${info.version}`;
  } catch { /* shown by the lists */ }
}

async function main() {
  const tok = $('token');
  tok.value = localStorage.getItem(TOKEN_KEY) || '';
  tok.onchange = () => { localStorage.setItem(TOKEN_KEY, tok.value.trim()); refreshAll(); showVersion(); };
  $('refresh').onclick = () => refreshAll();
  $('cancel').onclick = () => cancelJob();
  setupDrop();
  await showVersion();
  try {
    const { load } = await import('/ui/js-yaml.mjs');
    spec = load(await (await fetch('/openapi.yaml')).text());
    setupForm();
  } catch (e) {
    $('notice').dataset.sticky = '1';
    notice(`The job form needs js-yaml, which this build lacks (${e.message}): build voxeld after npm ci --prefix tools/viewer.`);
  }
  await refreshAll();
  // #job=ID opens that job: at load, and when the address changes (Back,
  // Forward, a link)
  const fromHash = () => {
    const m = /^#job=([0-9a-f]{32})$/.exec(location.hash);
    if (m && current?.id !== m[1]) openJob(m[1]);
  };
  window.addEventListener('hashchange', fromHash);
  fromHash();
  document.body.dataset.ready = '1';
}

main();
