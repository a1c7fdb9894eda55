// Drives the viewer (viewer/, served at /) in Debian's chromium through
// playwright-core (tools/viewer/package-lock.json): the token field, an
// upload through the file control and one by a synthetic drop, a voxelize
// and a gregory job from the generated form, each 3D result read back from
// the canvas (pixels that differ from the background), live progress from
// an event stream, a render turntable playing, gregory's frames played in
// order (70 of them), a download's name, the keyboard (the focus kept
// across the list's redraw), the open job kept in the address, a mesh
// chosen marked, a name with invisible characters, polling a server that
// answers ?wait at once, the version shown after the token, and the /docs
// page. Run by
// tests/integration/test_viewer.sh:
//   node viewer.cjs BASE TOKEN SPOT_OBJ CONTROL_OBJ OUT_DIR
// Prints one line per check; exits 1 when one fails.
const fs = require('fs');
const path = require('path');
const { chromium } = require('playwright-core');
const yaml = require('js-yaml');

const [base, token, spotObj, controlObj, outDir] = process.argv.slice(2);
const chromiumPath = process.env.VX_CHROMIUM || '/usr/bin/chromium';
let failed = 0;
function check(what, ok, detail = '') {
  console.log(`${ok ? 'ok' : 'FAIL'}: ${what}${detail ? ` (${detail})` : ''}`);
  if (!ok) failed++;
}

// Pixels of the 3D view that are not its background (viewer/view3d.js
// BACKGROUND 0x20242a), and the total.
async function drawnPixels(page) {
  return page.evaluate(() => {
    const c = document.getElementById('view3d');
    const o = document.createElement('canvas');
    o.width = c.width;
    o.height = c.height;
    const g = o.getContext('2d');
    g.drawImage(c, 0, 0);
    const d = g.getImageData(0, 0, o.width, o.height).data;
    let n = 0;
    for (let i = 0; i < d.length; i += 4)
      if (Math.abs(d[i] - 0x20) + Math.abs(d[i + 1] - 0x24) + Math.abs(d[i + 2] - 0x2a) > 30) n++;
    return { n, total: o.width * o.height };
  });
}

// Chooses kind, sets the given form fields, submits, and waits until the
// page shows the result (body[data-result-shown]) or the job failed.
async function runJob(page, kind, fields, shown) {
  await page.selectOption('#kind', kind);
  for (const [name, value] of Object.entries(fields)) {
    const f = page.locator(`#params [data-field="${name}"] :is(input, select, textarea)`);
    if ((await f.evaluate(e => e.tagName)) === 'SELECT') await f.selectOption(JSON.stringify(value));
    else await f.fill(typeof value === 'object' ? JSON.stringify(value) : String(value));
  }
  // (the last job's result may still be marked shown: same kind, same mark)
  await page.evaluate(() => { delete document.body.dataset.resultShown; delete document.body.dataset.jobState; });
  await page.click('#submit');
  await page.waitForFunction(
    want => document.body.dataset.resultShown === want || ['failed', 'canceled'].includes(document.body.dataset.jobState),
    shown, { timeout: 60000 });
  const state = await page.textContent('#state');
  check(`${kind}: the job succeeded`, /succeeded/.test(state), `${state} ${await page.textContent('#job-error')}`);
  const params = JSON.parse(await page.textContent('#job-json')).params;
  for (const [name, value] of Object.entries(fields)) {
    const got = typeof value === 'object' ? Object.fromEntries(Object.keys(value).map(k => [k, params[name]?.[k]])) : params[name];
    check(`${kind}: params.${name} from the form`, JSON.stringify(got) === JSON.stringify(value), JSON.stringify(params[name]));
  }
}

(async () => {
  fs.mkdirSync(outDir, { recursive: true });
  const browser = await chromium.launch({
    executablePath: chromiumPath,
    // WebGL without a GPU: ANGLE on SwiftShader (chromium's software Vulkan).
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
  });
  const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  const errors = [];
  page.on('pageerror', e => errors.push(e.message));
  await page.goto(`${base}/`);
  await page.waitForFunction(() => document.body.dataset.ready === '1', null, { timeout: 20000 });
  // One field per property of each kind's params schema in the contract.
  const spec = yaml.load(await (await fetch(`${base}/openapi.yaml`)).text());
  const kinds = await page.locator('#kind option').evaluateAll(os => os.map(o => o.value));
  check('the form lists every kind of x-kinds', JSON.stringify(kinds) === JSON.stringify(Object.keys(spec['x-kinds'])), kinds.join(' '));
  for (const k of kinds) {
    await page.selectOption('#kind', k);
    const fields = await page.locator('#params .field').evaluateAll(fs => fs.map(f => f.dataset.field));
    const ref = spec['x-kinds'][k].params.$ref.split('/').pop();
    const want = Object.keys(spec.components.schemas[ref].properties);
    check(`the ${k} form has a field per params property`, JSON.stringify(fields) === JSON.stringify(want), fields.join(' '));
  }
  if (token) {
    check('without a token the page asks for one', /token/.test(await page.textContent('#notice')));
    await page.fill('#token', token);
    await page.dispatchEvent('#token', 'change');
    await page.waitForFunction(() => document.getElementById('notice').hidden, null, { timeout: 10000 });
    // /v1/info was 401 before the token: asked again (the version stayed empty)
    await page.waitForFunction(() => /^v\d/.test(document.getElementById('server-info').textContent), null, { timeout: 10000 }).catch(() => {});
    check('the server version shows once the token is entered', /^v\d/.test(await page.textContent('#server-info')), await page.textContent('#server-info'));
  }

  // Upload by the file control.
  await page.setInputFiles('#file', spotObj);
  const spotName = path.basename(spotObj);
  await page.waitForFunction(n => document.getElementById('upload-status').textContent.startsWith(`${n}: mesh`), spotName, { timeout: 20000 });
  check('upload by the file control', (await page.locator('#meshes li').count()) === 1);
  await runJob(page, 'voxelize', { resolution: 32, format: 'binvox' }, 'voxels');
  let px = await drawnPixels(page);
  check('voxelize: the 3D view draws the grid', px.n > 0.02 * px.total && px.n < px.total, `${px.n} of ${px.total} pixels`);
  await page.locator('#right').screenshot({ path: path.join(outDir, 'viewer-voxelize.png') });

  // Upload by a synthetic drop of the control cage.
  const text = fs.readFileSync(controlObj, 'utf8');
  const dt = await page.evaluateHandle(([t, n]) => {
    const d = new DataTransfer();
    d.items.add(new File([t], n, { type: '' }));
    return d;
  }, [text, path.basename(controlObj)]);
  await page.dispatchEvent('#drop', 'drop', { dataTransfer: dt });
  await page.waitForFunction(n => document.getElementById('upload-status').textContent.startsWith(`${n}: mesh`), path.basename(controlObj), { timeout: 20000 });
  check('upload by drag and drop', (await page.locator('#meshes li').count()) === 2);
  // Live progress by Server-Sent Events: the server's own stream where it
  // has one (passed through), else one made of the job's real states (what
  // GET /v1/jobs/{id}/events sends: "event: job" + "data: <Job>"), so that
  // the page's stream reader is what follows this job, not polling.
  let streamed = 0;
  const polls = [];
  const onRequest = r => { if (/\/v1\/jobs\/[0-9a-f]+\?wait=/.test(r.url())) polls.push(r.url()); };
  page.on('request', onRequest);
  await page.route(/\/v1\/jobs\/[0-9a-f]+\/events$/, async route => {
    const url = route.request().url(), jid = url.match(/jobs\/([0-9a-f]+)\/events/)[1];
    const real = await route.fetch();
    streamed++;
    if (real.status() !== 404) return route.fulfill({ response: real });
    const done = await (await route.fetch({ url: `${base}/v1/jobs/${jid}?wait=50` })).json();
    const ev = j => `event: job\ndata: ${JSON.stringify(j)}\n\n`;
    return route.fulfill({ status: 200, headers: { 'Content-Type': 'text/event-stream' },
      body: `: voxeld\n\n${ev({ ...done, state: 'running', progress: 0.5, finished: null, outputs: {} })}${ev(done)}` });
  });
  await runJob(page, 'gregory', { divisions: 3 }, 'mesh');
  check('gregory: followed by its event stream, not by polling', streamed === 1 && polls.length === 0, `${streamed} streams, ${polls.length} polls`);
  page.off('request', onRequest);
  await page.unroute(/\/v1\/jobs\/[0-9a-f]+\/events$/);
  px = await drawnPixels(page);
  check('gregory: the 3D view draws the mesh', px.n > 0.02 * px.total && px.n < px.total, `${px.n} of ${px.total} pixels`);
  await page.screenshot({ path: path.join(outDir, 'viewer.png') });
  await page.locator('#right').screenshot({ path: path.join(outDir, 'viewer-gregory.png') });
  await page.click('#refresh');
  await page.waitForFunction(() => document.querySelectorAll('#jobs li').length === 2, null, { timeout: 10000 });
  const first = await page.textContent('#jobs li:first-child b');
  check('jobs are listed newest first', first === 'gregory', first);

  // No stream and no ?wait hold to spare (503 too_many_streams, then 503
  // too_many_waits, as a daemon at --max-event-streams and --max-waits
  // answers): the job is followed by plain GETs, and the page never says
  // the server is not answering.
  const busy = code => route => route.fulfill({ status: 503,
    headers: { 'Content-Type': 'application/json', 'Retry-After': '1' },
    body: JSON.stringify({ error: { code, message: 'the most it allows' } }) });
  await page.route(/\/v1\/jobs\/[0-9a-f]+\/events$/, busy('too_many_streams'));
  await page.route(/\/v1\/jobs\/[0-9a-f]+\?wait=/, busy('too_many_waits'));
  let plainGets = 0;
  const onPlain = r => { if (/\/v1\/jobs\/[0-9a-f]{32}$/.test(r.url())) plainGets++; };
  page.on('request', onPlain);
  await page.evaluate(() => {
    window.notAnswering = [];
    const e = document.getElementById('job-error');
    new MutationObserver(() => { if (/not answering/.test(e.textContent)) window.notAnswering.push(e.textContent); })
      .observe(e, { childList: true, characterData: true, subtree: true });
  });
  await runJob(page, 'render', { N: 64, width: 512, height: 512 }, 'image');
  const said = await page.evaluate(() => window.notAnswering);
  check('waits and streams full: followed by plain GETs, never "not answering"',
    said.length === 0 && plainGets >= 2, `${plainGets} plain GETs; ${said.join('; ')}`);
  page.off('request', onPlain);
  await page.unroute(/\/v1\/jobs\/[0-9a-f]+\/events$/);
  await page.unroute(/\/v1\/jobs\/[0-9a-f]+\?wait=/);

  // A render turntable on spot: its frames play in turn.
  await page.selectOption('#mesh', { label: await page.locator('#mesh option', { hasText: '5856 tris' }).textContent() });
  await runJob(page, 'render', { N: 16, width: 64, height: 48, frames: 3, camera: { type: 'orbit' } }, 'image');
  const srcs = new Set();
  for (let i = 0; i < 12; i++) {
    srcs.add(await page.getAttribute('#images img', 'src'));
    await page.waitForTimeout(40);
  }
  check('render: the turntable plays its frames', srcs.size >= 2, `${srcs.size} frames seen`);
  await page.locator('#right').screenshot({ path: path.join(outDir, 'viewer-render.png') });
  // A download keeps the server's file name (Content-Disposition), with its
  // extension (it was "<id>-image", no extension, for every format).
  const [dl] = await Promise.all([page.waitForEvent('download', { timeout: 20000 }),
    page.click('#outputs li:first-child a')]);
  check('a download is named as the server names it', /-image(_\d+)?\.png$/.test(dl.suggestedFilename()), dl.suggestedFilename());
  // The keyboard: a params field has its name as label, a job in the list
  // opens on Enter.
  check('a params field is labelled by its name', (await page.getByLabel('width', { exact: true }).count()) === 1);
  await page.focus('#jobs li:last-child');
  await page.keyboard.press('Enter');
  const lastId = await page.getAttribute('#jobs li:last-child', 'data-id');
  await page.waitForFunction(id => document.getElementById('job-title').textContent === id.slice(0, 12), lastId, { timeout: 10000 })
    .catch(() => {});
  check('a job opens on Enter', (await page.textContent('#job-title')) === lastId.slice(0, 12), await page.textContent('#job-title'));
  // ... and keeps the keyboard's focus while the list is rebuilt (it went
  // to the page's body)
  await page.waitForTimeout(1000);
  const focus = await page.evaluate(() => `${document.activeElement.tagName} ${document.activeElement.dataset.id || ''}`);
  check('the job opened keeps the focus', focus === `LI ${lastId}`, focus);
  // The open job is in the address: a reload shows it again.
  check('the open job is in the address', page.url().endsWith(`#job=${lastId}`), page.url());
  await page.reload();
  await page.waitForFunction(id => document.body.dataset.ready === '1' && document.getElementById('job-title').textContent === id.slice(0, 12),
    lastId, { timeout: 20000 }).catch(() => {});
  check('a reload shows the same job', (await page.textContent('#job-title')) === lastId.slice(0, 12), await page.textContent('#job-title'));

  // Deformation frames play after the job's mesh, in order: a gregory job
  // of the control cage with one frame (every vertex moved), opened from
  // the address. The page had fetched the mesh twice and never frame_001.
  const auth = token ? { Authorization: `Bearer ${token}` } : {};
  const meshes = await (await fetch(`${base}/v1/meshes?limit=100`, { headers: auth })).json();
  const cage = meshes.items.find(m => m.name === path.basename(controlObj));
  const frame = text.split('\n').filter(l => l.startsWith('v ')).flatMap(l => l.trim().split(/\s+/).slice(1, 4).map((v, i) => Number(v) * (i === 0 ? 1.2 : 1)));
  const gj = await (await fetch(`${base}/v1/jobs?wait=60`, { method: 'POST', headers: { ...auth, 'Content-Type': 'application/json' },
    body: JSON.stringify({ mesh: cage.id, kind: 'gregory', params: { divisions: 2, frames: [frame] } }) })).json();
  const fetched = [];
  // only this job's: the page left behind may still fetch its own job's
  const onResult = r => { const m = /\/v1\/jobs\/([0-9a-f]{32})\/result\/(\w+)$/.exec(r.url()); if (m && m[1] === gj.id) fetched.push(m[2]); };
  page.on('request', onResult);
  await page.goto(`${base}/#job=${gj.id}`);
  await page.waitForFunction(() => /\(2 frames\)/.test(document.getElementById('images').textContent), null, { timeout: 30000 }).catch(() => {});
  page.off('request', onResult);
  check('gregory frames: the mesh, then frame_001', JSON.stringify(fetched) === '["mesh","frame_001"]', `${gj.state} ${JSON.stringify(fetched)}`);

  // More deformation frames than 64 all play (the page took the first 64).
  const many = await (await fetch(`${base}/v1/jobs?wait=120`, { method: 'POST', headers: { ...auth, 'Content-Type': 'application/json' },
    body: JSON.stringify({ mesh: cage.id, kind: 'gregory', params: { divisions: 1, frames: Array.from({ length: 70 }, (_, k) => frame.map(x => x * (1 + k / 100))) } }) })).json();
  await page.goto(`${base}/#job=${many.id}`);
  await page.waitForFunction(() => /frames\)/.test(document.getElementById('images').textContent), null, { timeout: 60000 }).catch(() => {});
  check('70 deformation frames: all played', /\(71 frames\)/.test(await page.textContent('#images')), `${many.state} ${await page.textContent('#images')}`);

  // A mesh clicked in the list is marked (nothing showed it was chosen).
  await page.click('#meshes li:last-child');
  const marked = await page.evaluate(() => [...document.querySelectorAll('#meshes li')].map(li => `${li.classList.contains('sel')}:${li.getAttribute('aria-pressed')}`).join(' '));
  check('a mesh clicked is marked', /^(false:false )*true:true$/.test(marked), marked);

  // A file name with invisible format characters the server refuses in a
  // name (U+2060, U+061C: 400 before) goes up with them made '_'.
  const dt2 = await page.evaluateHandle(t => {
    const d = new DataTransfer();
    d.items.add(new File([`${t}\n# another file\n`], 'w\u2060j\u061c.obj', { type: '' }));
    return d;
  }, text);
  await page.dispatchEvent('#drop', 'drop', { dataTransfer: dt2 });
  await page.waitForFunction(() => /\.obj: (mesh|\d)/.test(document.getElementById('upload-status').textContent), null, { timeout: 20000 }).catch(() => {});
  const named = (await (await fetch(`${base}/v1/meshes?limit=100`, { headers: auth })).json()).items.map(m => m.name);
  check('a name with U+2060 and U+061C: uploaded as w_j_.obj', named.includes('w_j_.obj'), `${await page.textContent('#upload-status')}; ${named.join(' ')}`);

  // A server that answers ?wait at once (--request-timeout 0) with no
  // stream is asked once a second (it was asked as fast as it answered):
  // the job is said running for 3 s.
  await page.route(/\/v1\/jobs\/[0-9a-f]+\/events$/, busy('too_many_streams'));
  let quick = 0, since = 0;
  const seen = [];
  const onSeen = r => seen.push(r.url().replace(base, ''));
  page.on('request', onSeen);
  const jobUrl = /\/v1\/jobs\/[0-9a-f]{32}(\?.*)?$/;
  await page.route(jobUrl, async route => {
    if (/\?wait=/.test(route.request().url())) quick++;
    since = since || Date.now();
    const real = await (await route.fetch({ url: route.request().url().replace(/\?.*/, '') })).json();
    const j = Date.now() - since < 3000 ? { ...real, state: 'running', progress: 0.5, finished: null, outputs: {} } : real;
    return route.fulfill({ status: 200, headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(j) });
  });
  const pj = await (await fetch(`${base}/v1/jobs?wait=60`, { method: 'POST', headers: { ...auth, 'Content-Type': 'application/json' },
    body: JSON.stringify({ mesh: cage.id, kind: 'gregory', params: { divisions: 1 } }) })).json();
  await page.goto('about:blank'); // a fresh page (the last one's 70 frames may still load)
  await page.goto(`${base}/#job=${pj.id}`);
  await page.waitForFunction(id => document.getElementById('job-title').textContent === id.slice(0, 12) &&
    /succeeded/.test(document.getElementById('state').textContent), pj.id, { timeout: 20000 }).catch(() => {});
  page.off('request', onSeen);
  check('?wait answered at once: polled about once a second', quick >= 2 && quick <= 6, `${quick} polls, ${await page.textContent('#state')}; ${seen.slice(0, 12).join(' ')}`);
  await page.unroute(/\/v1\/jobs\/[0-9a-f]+\/events$/);
  await page.unroute(jobUrl);

  // The reference page.
  await page.goto(`${base}/docs`);
  await page.waitForFunction(() => document.body.dataset.ready === '1', null, { timeout: 20000 });
  const ops = await page.locator('.doc .op h3 .method').count();
  check('/docs renders every operation', ops >= 10, `${ops} operations`);
  check('no script errors', errors.length === 0, errors.join('; '));
  await browser.close();
  process.exit(failed ? 1 : 0);
})().catch(e => {
  console.log(`FAIL: ${e.message}`);
  process.exit(1);
});
