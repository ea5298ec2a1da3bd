// The viewer page in headless Chromium against a running `transtick view`
// (tests/web_viewer_test.sh starts it and passes what it needs here):
//
//   TRANSTICK_VIEW_URL   the gateway's page, http://127.0.0.1:PORT/
//   TRANSTICK_ROOT       the embedded cluster's root, for `transtick submit`
//   TRANSTICK_BIN        the transtick CLI (reference renders, submit)
//   TRANSTICK_DATA_DIR   the data directory, holding cthead.nrrd
//   WEB_TEST_DIR         where playwright-core is installed
//   WEB_TEST_TMP         a scratch directory
//   TRANSTICK_SCREENSHOT optional: where to save a screenshot of the page
//   TRANSTICK_CHROMIUM   the browser (default /usr/bin/chromium)
//
// Every image check is exact: the page's PNG and the CLI's in-process render
// of the same view and classification decode to the same RGB bytes.

import {execFile, spawn} from 'node:child_process';
import {createRequire} from 'node:module';
import fs from 'node:fs';
import path from 'node:path';
import {promisify} from 'node:util';
import zlib from 'node:zlib';

const env = (name) => {
  const v = process.env[name];
  if (!v) throw new Error(`${name} is not set`);
  return v;
};
const URL_ = env('TRANSTICK_VIEW_URL');
const ROOT = env('TRANSTICK_ROOT');
const BIN = env('TRANSTICK_BIN');
const DATA = env('TRANSTICK_DATA_DIR');
const TMP = env('WEB_TEST_TMP');
const require = createRequire(path.join(env('WEB_TEST_DIR'), 'package.json'));
const {chromium} = require('playwright-core');

const run = promisify(execFile);
const t0 = Date.now();
const timings = [];
const results = [];
let failed = 0;

// `latency`: the page's own figure, from sending the request to showing its frame.
function timing(name, ms, latency) {
  timings.push([name, ms]);
  console.log(`timing: ${name} ${ms.toFixed(0)} ms${latency ? ` (the page's latency: ${latency})` : ''}`);
}

// Runs one named check; a failure is reported with its name and the run goes on.
async function check(name, fn) {
  const start = Date.now();
  try {
    await fn();
    results.push([name, true]);
    console.log(`ok   ${name} (${Date.now() - start} ms)`);
    return true;
  } catch (e) {
    failed++;
    results.push([name, false]);
    console.log(`FAIL ${name}: ${e.message}`);
    return false;
  }
}

function assert(cond, message) {
  if (!cond) throw new Error(message);
}

// ------------------------------------------------------------ PNG decoding

// Decodes an 8-bit, non-interlaced PNG (grey, RGB, grey+alpha or RGBA) to RGB.
function decodePng(buf) {
  const sig = [137, 80, 78, 71, 13, 10, 26, 10];
  assert(buf.length > 8 && sig.every((b, i) => buf[i] === b), 'not a PNG');
  let pos = 8;
  let ihdr = null;
  const idat = [];
  while (pos + 8 <= buf.length) {
    const len = buf.readUInt32BE(pos);
    const type = buf.toString('latin1', pos + 4, pos + 8);
    const data = buf.subarray(pos + 8, pos + 8 + len);
    pos += 12 + len;
    if (type === 'IHDR') {
      ihdr = {width: data.readUInt32BE(0), height: data.readUInt32BE(4), depth: data[8], color: data[9],
              interlace: data[12]};
    } else if (type === 'IDAT') {
      idat.push(data);
    } else if (type === 'IEND') {
      break;
    }
  }
  assert(ihdr, 'PNG without IHDR');
  const channels = {0: 1, 2: 3, 4: 2, 6: 4}[ihdr.color];
  assert(ihdr.depth === 8 && channels && ihdr.interlace === 0,
         `PNG depth ${ihdr.depth}, colour type ${ihdr.color}, interlace ${ihdr.interlace}: not decoded here`);
  const raw = zlib.inflateSync(Buffer.concat(idat));
  const {width, height} = ihdr;
  const stride = width * channels;
  assert(raw.length >= height * (stride + 1), 'PNG data too short');
  const px = Buffer.alloc(height * stride);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    const line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    const out = px.subarray(y * stride, (y + 1) * stride);
    const prev = y > 0 ? px.subarray((y - 1) * stride, y * stride) : null;
    for (let i = 0; i < stride; i++) {
      const a = i >= channels ? out[i - channels] : 0;
      const b = prev ? prev[i] : 0;
      const c = prev && i >= channels ? prev[i - channels] : 0;
      let v;
      switch (filter) {
        case 0: v = line[i]; break;
        case 1: v = line[i] + a; break;
        case 2: v = line[i] + b; break;
        case 3: v = line[i] + ((a + b) >> 1); break;
        case 4: {
          const p = a + b - c;
          const pa = Math.abs(p - a);
          const pb = Math.abs(p - b);
          const pc = Math.abs(p - c);
          v = line[i] + (pa <= pb && pa <= pc ? a : pb <= pc ? b : c);
          break;
        }
        default: throw new Error(`PNG filter ${filter}`);
      }
      out[i] = v & 255;
    }
  }
  const rgb = Buffer.alloc(width * height * 3);
  for (let i = 0; i < width * height; i++) {
    const g = channels <= 2;
    rgb[i * 3] = px[i * channels];
    rgb[i * 3 + 1] = px[i * channels + (g ? 0 : 1)];
    rgb[i * 3 + 2] = px[i * channels + (g ? 0 : 2)];
  }
  return {width, height, rgb};
}

// Throws unless the two PNGs have the same size and RGB bytes.
function assertSamePixels(pagePng, cliPng, what) {
  const a = decodePng(Buffer.from(pagePng));
  const b = decodePng(Buffer.from(cliPng));
  assert(a.width === b.width && a.height === b.height,
         `${what}: page image ${a.width}x${a.height}, CLI image ${b.width}x${b.height}`);
  let diff = 0;
  let maxd = 0;
  let first = -1;
  for (let i = 0; i < a.rgb.length; i++) {
    const d = Math.abs(a.rgb[i] - b.rgb[i]);
    if (d) {
      diff++;
      maxd = Math.max(maxd, d);
      if (first < 0) first = i;
    }
  }
  if (diff) {
    const p = Math.floor(first / 3);
    throw new Error(`${what}: ${diff} of ${a.rgb.length} channel values differ (largest by ${maxd}; first at ` +
                    `pixel ${p % a.width},${Math.floor(p / a.width)})`);
  }
}

function samePng(a, b) {
  return Buffer.from(a).equals(Buffer.from(b));
}

// ------------------------------------------------------------ the CLI

let cliRenders = 0;

// The in-process reference render of `view` (a page View) with `classify`:
// ['--preset', 'ct-bone'] or ['--materials', FILE].
// In dvr mode (`dvr`) shadows are not a thing: the CLI refuses --shadows.
async function cliRender(view, classify, dvr = false, volume = 'cthead.nrrd') {
  const out = path.join(TMP, `cli_${++cliRenders}.png`);
  const args = ['render', '--volume', path.join(DATA, volume), ...classify,
    '--azimuth', String(view.azimuth), '--elevation', String(view.elevation), '--zoom', String(view.zoom),
    '--size', `${view.width}x${view.height}`, ...(dvr ? [] : ['--shadows', view.shadows ? 'on' : 'off']),
    '--samples', String(view.samples), '--projection', view.projection.toLowerCase(),
    '--local', '0', '--quiet', '--out', out];
  const start = Date.now();
  try {
    await run(BIN, args, {timeout: 60000});
  } catch (e) {
    throw new Error(`transtick ${args.join(' ')} failed: ${(e.stderr || e.message).trim()}`);
  }
  timing(`CLI render ${cliRenders}`, Date.now() - start);
  return fs.readFileSync(out);
}

function writeJob(name, views, size) {
  const file = path.join(TMP, `${name.replace(/\W+/g, '_')}.json`);
  const job = {
    name,
    datasets: [{
      volume: 'cthead.nrrd',
      preset: {name: 'ct-bone'},
      views: Array.from({length: views}, (_, i) => ({azimuth: (360 * i) / views, width: size, height: size,
                                                     output: `${name.replace(/\W+/g, '_')}_${i}.png`})),
    }],
  };
  fs.writeFileSync(file, JSON.stringify(job));
  return file;
}

// ------------------------------------------------------------ the page

const browser = await chromium.launch({
  executablePath: process.env.TRANSTICK_CHROMIUM || '/usr/bin/chromium',
  args: ['--no-sandbox'],
});
const context = await browser.newContext({viewport: {width: 1280, height: 720}});
const page = await context.newPage();
const pageProblems = [];
page.on('pageerror', (e) => pageProblems.push(`page error: ${e.message}`));
page.on('console', (m) => {
  if (m.type() === 'error') pageProblems.push(`console error: ${m.text()}`);
});
// Every classification the page sends, as sent.
const sentBodies = [];
page.on('request', (r) => {
  if (r.method() === 'POST' && /\/api\/sessions\/[^/]+$/.test(new URL(r.url()).pathname)) {
    try {
      sentBodies.push(JSON.parse(r.postData() || '{}'));
    } catch {
      // not JSON: the gateway answers it
    }
  }
});

// The page's transtickViewer, its PNG carried over as base64.
const viewer = async () => {
  const s = await page.evaluate(() => {
    const v = window.transtickViewer;
    const f = v.lastFrame;
    let b64 = '';
    if (f) {
      let bin = '';
      for (let i = 0; i < f.png.length; i += 0x8000) bin += String.fromCharCode(...f.png.subarray(i, i + 0x8000));
      b64 = btoa(bin);
    }
    return {view: v.view, frames: v.frames, lastFrame: f && {seq: f.seq, preview: f.preview, view: f.view, png: b64}};
  });
  if (s.lastFrame) s.lastFrame.png = Buffer.from(s.lastFrame.png, 'base64');
  return s;
};

// Waits for a full frame of the page's current view; with `afterSeq`, one
// of a later request; with `afterFrames`, one after that many full frames.
// Returns the viewer's state and the wait.
async function fullFrameOfView(what, afterSeq = -1, timeout = 30000, afterFrames = -1) {
  const start = Date.now();
  try {
    await page.waitForFunction(([after, frames]) => {
      const v = window.transtickViewer;
      const f = v.lastFrame;
      return f && !f.preview && f.seq > after && v.frames > frames &&
             JSON.stringify(f.view) === JSON.stringify(v.view);
    }, [afterSeq, afterFrames], {timeout});
  } catch (e) {
    const s = await viewer().catch(() => null);
    const status = await page.textContent('#status').catch(() => '?');
    throw new Error(`${what}: no full frame of the page's view within ${timeout / 1000} s ` +
                    `(view ${JSON.stringify(s && s.view)}, last frame ${JSON.stringify(s && s.lastFrame &&
                    {...s.lastFrame, png: s.lastFrame.png.length})}; status: ${status})`);
  }
  const ms = Date.now() - start;
  const s = await viewer();
  const latency = await page.textContent('#stat-latency');
  return {...s, ms, latency};
}

let state = null;   // the viewer after the last frame checked
let dims = null;

const openStart = Date.now();
await page.goto(`${URL_}?volume=cthead.nrrd&preset=ct-bone`);

const opened = await check('open cthead.nrrd with ct-bone from the URL: first full frame', async () => {
  state = await fullFrameOfView('first frame', -1, 60000);
  timing('first frame (page load to full frame)', Date.now() - openStart, state.latency);
  const v = state.view;
  assert(v.azimuth === 0 && v.elevation === 0 && v.zoom === 1 && v.width === 400 && v.height === 400 &&
         v.shadows === true && v.samples === 1 && v.projection === 'PERSPECTIVE',
         `the first view is ${JSON.stringify(v)}, not the default`);
  assert(state.frames >= 1, `frames is ${state.frames}`);
});

if (!opened) {
  console.log(`status line: ${await page.textContent('#status').catch(() => '?')}`);
  await browser.close();
  console.log(`0 passed, ${failed} failed`);
  process.exit(1);
}

await check('first frame equals the CLI render of the same view', async () => {
  assertSamePixels(state.lastFrame.png, await cliRender(state.view, ['--preset', 'ct-bone']), 'first frame');
});

await check('histogram canvas is drawn', async () => {
  const r = await page.evaluate(() => {
    const c = document.getElementById('histogram');
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    const bg = [d[0], d[1], d[2]];
    let other = 0;
    const colours = new Set();
    for (let i = 0; i < d.length; i += 4) {
      if (d[i] !== bg[0] || d[i + 1] !== bg[1] || d[i + 2] !== bg[2]) other++;
      colours.add((d[i] << 16) | (d[i + 1] << 8) | d[i + 2]);
    }
    return {other, total: d.length / 4, colours: colours.size};
  });
  assert(r.other > r.total * 0.05 && r.colours > 4,
         `only ${r.other} of ${r.total} pixels differ from the background, ${r.colours} colours`);
});

await check('workers table: 2 rows whose slabs tile the volume\u2019s Y range', async () => {
  const header = fs.readFileSync(path.join(DATA, 'cthead.nrrd')).subarray(0, 2000).toString('latin1');
  const sizes = /^sizes:\s*(\d+)\s+(\d+)\s+(\d+)/m.exec(header);
  assert(sizes, 'cthead.nrrd: no sizes line');
  dims = sizes.slice(1).map(Number);
  const shown = await page.getAttribute('#volume-info', 'data-dims');
  assert(shown === dims.join(','), `the page shows dims ${shown}, the file says ${dims.join(',')}`);
  const rows = await page.$$eval('#workers tbody tr', (trs) => trs.map((tr) => ({
    begin: Number(tr.dataset.slabBegin), end: Number(tr.dataset.slabEnd), cells: tr.cells.length,
    text: tr.textContent,
  })));
  assert(rows.length === 2, `${rows.length} rows: ${JSON.stringify(rows.map((r) => r.text))}`);
  const slabs = rows.map((r) => [r.begin, r.end]).sort((a, b) => a[0] - b[0]);
  assert(slabs[0][0] === 0 && slabs[0][1] === slabs[1][0] && slabs[1][1] === dims[1] &&
         slabs.every(([b, e]) => e > b),
         `slabs ${JSON.stringify(slabs)} do not tile [0, ${dims[1]})`);
  const imbalance = await page.textContent('#imbalance');
  assert(/active imbalance \d/.test(imbalance), `imbalance line: '${imbalance}'`);
});

await check('job list shows a job submitted with transtick submit', async () => {
  const name = 'web viewer test job';
  const start = Date.now();
  try {
    await run(BIN, ['submit', '--root', ROOT, writeJob(name, 2, 64), '--out-dir', TMP, '--quiet'],
              {timeout: 60000});
  } catch (e) {
    throw new Error(`transtick submit failed: ${(e.stderr || e.message).trim()}`);
  }
  timing('submit of a 2-frame job', Date.now() - start);
  try {
    await page.waitForFunction((n) => [...document.querySelectorAll('#jobs tbody tr')].some(
      (tr) => tr.cells[0].textContent === n && tr.dataset.state === 'DONE' && /2\/2/.test(tr.textContent)),
      name, {timeout: 10000});
  } catch {
    const rows = await page.$$eval('#jobs tbody tr', (trs) => trs.map((tr) => tr.textContent));
    throw new Error(`no row '${name}' done 2/2 within 10 s; rows: ${JSON.stringify(rows)}`);
  }
  const info = await page.textContent('#cluster-info');
  assert(/^2 workers, 1 ring$/.test(info), `cluster line '${info}'`);
});

await check('drag orbits: a new frame of the new view, equal to the CLI render', async () => {
  const before = state;
  const box = await page.locator('#viewport').boundingBox();
  const x = box.x + box.width / 2;
  const y = box.y + box.height / 2;
  await page.mouse.move(x, y);
  await page.mouse.down();
  for (let i = 1; i <= 12; i++) await page.mouse.move(x + 10 * i, y - (40 * i) / 12);
  await page.mouse.up();
  state = await fullFrameOfView('drag');
  timing('drag to full frame', state.ms, state.latency);
  const v = state.view;
  assert(Math.abs(v.azimuth - 48) < 1e-9 && Math.abs(v.elevation - 16) < 1e-9,
         `after a drag of 120 px right and 40 px up, azimuth ${v.azimuth} and elevation ${v.elevation} ` +
         '(want 48 and 16)');
  assert(!samePng(state.lastFrame.png, before.lastFrame.png), 'the PNG did not change');
  assertSamePixels(state.lastFrame.png, await cliRender(v, ['--preset', 'ct-bone']), 'after the drag');
});

if (process.env.TRANSTICK_SCREENSHOT) {
  await check('screenshot', async () => {
    // The dragged view with 4 samples per pixel, as the README's demo has;
    // then back to 1, so the checks below see the same views either way.
    const before = state;
    await page.selectOption('#samples', '4');
    await fullFrameOfView('4 samples', before.lastFrame.seq);
    await page.screenshot({path: process.env.TRANSTICK_SCREENSHOT});
    console.log(`screenshot: ${process.env.TRANSTICK_SCREENSHOT}`);
    await page.selectOption('#samples', '1');
    state = await fullFrameOfView('1 sample again', before.lastFrame.seq);
  });
}

await check('wheel zooms: a new frame of the zoomed view', async () => {
  const before = state;
  await page.mouse.wheel(0, -200);
  state = await fullFrameOfView('wheel');
  timing('wheel to full frame', state.ms, state.latency);
  const want = before.view.zoom * 1.1 ** 2;
  assert(Math.abs(state.view.zoom - want) < 1e-9, `zoom ${state.view.zoom}, want ${want}`);
  assert(!samePng(state.lastFrame.png, before.lastFrame.png), 'the PNG did not change');
});

await check('keyboard: ArrowRight on the focused image turns the azimuth by 5°', async () => {
  const before = state;
  await page.focus('#viewport');
  await page.keyboard.press('ArrowRight');
  state = await fullFrameOfView('ArrowRight');
  timing('key to full frame', state.ms, state.latency);
  const want = before.view.azimuth + 5;
  assert(Math.abs(state.view.azimuth - want) < 1e-9, `azimuth ${state.view.azimuth}, want ${want}`);
  assert(!samePng(state.lastFrame.png, before.lastFrame.png), 'the PNG did not change');
});

await check('shadows off: a new frame, equal to the CLI render with --shadows off', async () => {
  const before = state;
  await page.click('#shadows');
  state = await fullFrameOfView('shadows off');
  timing('shadows toggle to full frame', state.ms, state.latency);
  assert(state.view.shadows === false, `view.shadows is ${state.view.shadows}`);
  assert(!samePng(state.lastFrame.png, before.lastFrame.png), 'the PNG did not change');
  assertSamePixels(state.lastFrame.png, await cliRender(state.view, ['--preset', 'ct-bone']), 'shadows off');
});

await check('classification edit (bone min 300 -> 1200) changes the frame, equal to the CLI render', async () => {
  const before = state;
  const min = page.locator('#class-editor .mat-min').first();
  assert(await min.inputValue() === '300', `the first material's min shows '${await min.inputValue()}'`);
  await min.fill('1200');
  await min.press('Enter');
  await page.click('#class-apply');
  const start = Date.now();
  state = await fullFrameOfView('classification', before.lastFrame.seq);
  timing('classification apply to full frame', Date.now() - start, state.latency);
  assert(!samePng(state.lastFrame.png, before.lastFrame.png), 'the PNG did not change');
  const sent = sentBodies.filter((b) => b.materials).pop();
  assert(sent && sent.materials.materials[0].min === 1200,
         `the page sent ${JSON.stringify(sent)}, not bone with min 1200`);
  const file = path.join(TMP, 'edited_materials.json');
  fs.writeFileSync(file, JSON.stringify(sent.materials));
  assertSamePixels(state.lastFrame.png, await cliRender(state.view, ['--materials', file]), 'edited materials');
  const applyDisabled = await page.isDisabled('#class-apply');
  assert(applyDisabled, 'Apply is still enabled after the classification came back');
});

let dvrOpen = false;
await check('Open with ct-bone in dvr mode from the pickers: a frame equal to the CLI render', async () => {
  const before = state;
  await page.selectOption('#preset', 'ct-bone|DVR');
  await page.click('#open');
  state = await fullFrameOfView('dvr open', -1, 60000, before.frames);
  timing('dvr session open to full frame', state.ms, state.latency);
  const mode = await page.textContent('#class-mode');
  assert(mode === 'dvr', `the editor's mode is '${mode}'`);
  assert(/[?&]mode=dvr/.test(page.url()), `the URL ${page.url()} does not say mode=dvr`);
  assertSamePixels(state.lastFrame.png, await cliRender(state.view, ['--preset', 'ct-bone', '--mode', 'dvr'], true),
                   'dvr');
  dvrOpen = true;
});

if (dvrOpen) {
  await check('transfer function edit (a point added on the canvas) changes the frame, equal to the CLI render',
              async () => {
    const before = state;
    const points = await page.locator('#class-editor tbody tr').count();
    const box = await page.locator('#histogram').boundingBox();
    await page.mouse.click(box.x + box.width * 0.45, box.y + 30);
    const after = await page.locator('#class-editor tbody tr').count();
    assert(after === points + 1, `a click on the canvas left ${after} points (had ${points})`);
    await page.click('#class-apply');
    const start = Date.now();
    state = await fullFrameOfView('transfer edit', before.lastFrame.seq);
    timing('transfer apply to full frame', Date.now() - start, state.latency);
    assert(!samePng(state.lastFrame.png, before.lastFrame.png), 'the PNG did not change');
    const sent = sentBodies.filter((b) => b.transfer).pop();
    assert(sent && sent.transfer.points.length === points + 1,
           `the page sent ${JSON.stringify(sent)}, not ${points + 1} points`);
    const file = path.join(TMP, 'edited_transfer.json');
    fs.writeFileSync(file, JSON.stringify(sent.transfer));
    assertSamePixels(state.lastFrame.png, await cliRender(state.view, ['--transfer', file], true), 'edited transfer');
  });
}

await check('Cancel button cancels a running job', async () => {
  const name = 'web viewer test long job';
  // Long enough to outlast the page's next look at the jobs and the click
  // on a loaded machine: 200 such frames once finished first (2 s), and the
  // job showed done, not cancelled. It is cancelled within its first frames.
  const submit = spawn(BIN, ['submit', '--root', ROOT, writeJob(name, 5000, 128), '--out-dir', TMP, '--quiet'],
                       {stdio: ['ignore', 'ignore', 'pipe']});
  let stderr = '';
  submit.stderr.on('data', (d) => { stderr += d; });
  try {
    const row = page.locator('#jobs tbody tr', {hasText: name});
    try {
      await row.locator('button', {hasText: 'Cancel'}).waitFor({timeout: 15000});
    } catch {
      throw new Error(`no row '${name}' with a Cancel button within 15 s (submit: ${stderr.trim() || 'no output'})`);
    }
    await row.locator('button', {hasText: 'Cancel'}).click();
    try {
      await page.waitForFunction((n) => [...document.querySelectorAll('#jobs tbody tr')].some(
        (tr) => tr.cells[0].textContent === n && tr.dataset.state === 'CANCELLED'), name, {timeout: 10000});
    } catch {
      const rows = await page.$$eval('#jobs tbody tr', (trs) => trs.map((tr) => tr.textContent));
      throw new Error(`the job is not cancelled within 10 s; rows: ${JSON.stringify(rows)}`);
    }
  } finally {
    if (submit.exitCode === null) submit.kill('SIGTERM');
  }
});

// A DICOM study in the data directory (tests/dicom_study, written there
// by web_viewer_test.sh): each series is offered as the path that opens it,
// with what its headers say; a series the reader would refuse is shown
// disabled, with why; a series opens and renders as the CLI renders it.
if (process.env.TRANSTICK_STUDY === '1') {
  await check('a DICOM study: each series listed and openable, a broken one disabled with why', async () => {
    const opts = await page.$$eval('#volume option',
                                   (os) => os.map((o) => ({value: o.value, text: o.textContent, disabled: o.disabled})));
    const shown = JSON.stringify(opts);
    const bone = opts.find((o) => o.value === 'study#1.2.840.99.1');
    assert(bone && !bone.disabled && bone.text.includes("[DICOM: CT, series 3 'AX BONE', 12 files, 16x16x12]"),
           `no enabled option for series 1.2.840.99.1 with its description: ${shown}`);
    const other = opts.find((o) => o.value === 'study#1.2.840.99.12');
    assert(other && !other.disabled && other.text.includes('CT, series 4, 6 files, 16x16x6'),
           `no enabled option for series 1.2.840.99.12: ${shown}`);
    assert(!opts.some((o) => o.value === 'study'), `the study's directory is offered as a volume: ${shown}`);
    const gap = opts.find((o) => o.value === 'gap');
    assert(gap && gap.disabled && gap.text.includes('a missing slice'),
           `the series with a gap is not disabled with its reason: ${shown}`);
    const before = state;
    await page.selectOption('#volume', 'study#1.2.840.99.1');
    await page.selectOption('#preset', 'ct-bone|SURFACES');
    await page.click('#open');
    state = await fullFrameOfView('DICOM series open', -1, 60000, before.frames);
    const info = await page.getAttribute('#volume-info', 'data-dims');
    assert(info === '16,16,12', `the page shows dims ${info}`);
    assertSamePixels(state.lastFrame.png,
                     await cliRender(state.view, ['--preset', 'ct-bone'], false, 'study#1.2.840.99.1'),
                     'DICOM series');
  });
}

await check('the page reported no errors', async () => {
  const errors = await page.$$eval('#log li.error', (lis) => lis.map((li) => li.textContent));
  const problems = [...pageProblems, ...errors.map((e) => `status line: ${e}`)];
  assert(problems.length === 0, problems.join('; '));
});

await browser.close();
timing('whole test', Date.now() - t0);
const passed = results.filter(([, ok]) => ok).length;
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
