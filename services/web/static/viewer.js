// transtick viewer: the page transtick-web serves (docs/viewer.md).
//
// It speaks the gateway's JSON API (docs/formats.md, "Web gateway"), by
// paths relative to the page (so a proxy may serve it under a prefix): it
// opens an interactive session, sends cameras and classifications with
// POST /api/sessions/ID, and long-polls the session's events, whose answer
// is binary (a little-endian u32 length, that much JSON, then the PNGs).
// No framework, no build step, nothing loaded from elsewhere: the gateway's
// CSP allows only this origin.

const SIZES = [256, 400, 512, 800];
const PROJECTIONS = ['PERSPECTIVE', 'ORTHOGRAPHIC'];
const TOKEN_KEY = 'transtick.token';
const PREVIEW = 4;           // preview at 1/4 of the width and height
const EVENTS_WAIT_S = 20;    // long-poll time the gateway may hold a poll
const STATUS_PERIOD_MS = 2000;

const $ = (id) => document.getElementById(id);

// ------------------------------------------------------------ small helpers

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k === 'class') e.className = v;
    else if (k === 'text') e.textContent = v;
    else if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v === true ? '' : v);
  }
  for (const c of children) e.append(c);
  return e;
}

const clamp = (x, lo, hi) => Math.min(hi, Math.max(lo, x));
const num = (x, fallback = 0) => {
  const n = Number(x);
  return Number.isFinite(n) ? n : fallback;
};
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

function fmtMs(x) {
  if (!Number.isFinite(x)) return '–';
  return x >= 100 ? `${x.toFixed(0)} ms` : `${x.toFixed(1)} ms`;
}

function fmtCount(x) {
  const n = Number(x || 0);
  if (n >= 1e9) return `${(n / 1e9).toFixed(2)} G`;
  if (n >= 1e6) return `${(n / 1e6).toFixed(2)} M`;
  if (n >= 1e4) return `${(n / 1e3).toFixed(1)} k`;
  return String(n);
}

// A number for an editor field: short, but exact enough to round-trip what
// the user typed or dragged to.
function fmtValue(x) {
  if (!Number.isFinite(x)) return '';
  return String(Number(x.toPrecision(7)));
}

function rgbHex(c) {
  const h = (v) => clamp(Math.round(num(v) * 255), 0, 255).toString(16).padStart(2, '0');
  return `#${h(c[0])}${h(c[1])}${h(c[2])}`;
}

function hexRgb(hex) {
  const m = /^#([0-9a-f]{2})([0-9a-f]{2})([0-9a-f]{2})$/i.exec(hex);
  if (!m) return [1, 1, 1];
  return [1, 2, 3].map((i) => Number((parseInt(m[i], 16) / 255).toFixed(4)));
}

function cssRgb(c, alpha = 1) {
  const b = (v) => clamp(Math.round(num(v) * 255), 0, 255);
  return `rgba(${b(c[0])}, ${b(c[1])}, ${b(c[2])}, ${alpha})`;
}

const clone = (x) => (x === undefined ? undefined : JSON.parse(JSON.stringify(x)));

// ------------------------------------------------------------ status line

const log = [];

// Shows a message in the status line and keeps it in the message log.
// kind: 'info', 'ok', 'warn' or 'error'.
function setStatus(text, kind = 'info') {
  const status = $('status');
  status.textContent = text;
  status.className = `status ${kind}`;
  const last = log[log.length - 1];
  if (last && last.text === text) {
    last.count++;
    last.li.querySelector('.count').textContent = ` ×${last.count}`;
    return;
  }
  const time = new Date().toLocaleTimeString();
  const li = el('li', {class: kind}, el('time', {text: time}), ` ${text}`, el('span', {class: 'count'}));
  $('log').prepend(li);
  log.push({text, count: 1, li});
  if (log.length > 50) log.shift().li.remove();
}

function showReopen(show) {
  $('reopen').hidden = !show;
}

// ------------------------------------------------------------ API

class ApiError extends Error {
  constructor(status, message) {
    super(message);
    this.status = status;
  }
}

function token() {
  try {
    return sessionStorage.getItem(TOKEN_KEY) || '';
  } catch {
    return '';
  }
}

function headers(json) {
  const h = {};
  const t = token();
  if (t) h.Authorization = `Bearer ${t}`;
  if (json) h['Content-Type'] = 'application/json';
  return h;
}

// A fetch of the API with the token; returns the Response. Shows the token
// field on 401.
async function apiFetch(method, path, body, signal) {
  const init = {method, headers: headers(body !== undefined), cache: 'no-store',
                credentials: 'omit', signal};
  if (body !== undefined) init.body = JSON.stringify(body);
  const r = await fetch(path, init);
  if (r.status === 401) needToken(token() ? 'The token was refused.' : 'This gateway needs a token.');
  return r;
}

// The error message of a failed answer: the gateway's {"error": ...}, or
// the body, or the status text.
async function errorOf(r) {
  let text = '';
  try {
    text = await r.text();
    const j = JSON.parse(text);
    if (j && typeof j.error === 'string') return new ApiError(r.status, j.error);
  } catch {
    // not JSON: the text itself
  }
  return new ApiError(r.status, `HTTP ${r.status}${text ? `: ${text.slice(0, 200)}` : ` ${r.statusText}`}`);
}

function authHint(e) {
  return e.status === 401 ? ' (enter a bearer token above)' : '';
}

async function api(method, path, body, signal) {
  const r = await apiFetch(method, path, body, signal);
  if (!r.ok) throw await errorOf(r);
  const text = await r.text();
  return text ? JSON.parse(text) : {};
}

// ------------------------------------------------------------ auth

// Shows the token field; says why once for each token (the job list asks
// every 2 s).
let tokenAsked = null;
function needToken(why) {
  const form = $('auth');
  if (form.hidden) $('token').focus();
  form.hidden = false;
  if (tokenAsked === token()) return;
  tokenAsked = token();
  setStatus(`${why} Enter a bearer token above.`, 'error');
}

function setupAuth() {
  $('token').value = token();
  $('auth').addEventListener('submit', (e) => {
    e.preventDefault();
    const t = $('token').value.trim();
    try {
      if (t) sessionStorage.setItem(TOKEN_KEY, t);
      else sessionStorage.removeItem(TOKEN_KEY);
    } catch (err) {
      setStatus(`Cannot keep the token in sessionStorage: ${err.message}`, 'error');
    }
    setStatus(t ? 'Token set.' : 'Token cleared.', 'ok');
    loadVolumes();
    pollStatus();
  });
  $('token-forget').addEventListener('click', () => {
    try {
      sessionStorage.removeItem(TOKEN_KEY);
    } catch {
      // nothing kept
    }
    $('token').value = '';
    setStatus('Token forgotten.', 'ok');
  });
}

// ------------------------------------------------------------ the view

const defaultCamera = () => ({azimuth: 0, elevation: 0, zoom: 1});

// The View sent to the root, with its fields always in this order and all
// given, so two views compare by JSON.stringify.
function normView(v) {
  return {
    azimuth: v.azimuth,
    elevation: v.elevation,
    zoom: v.zoom,
    projection: v.projection,
    width: v.width,
    height: v.height,
    shadows: v.shadows,
    samples: v.samples,
  };
}

let view = normView({...defaultCamera(), projection: 'PERSPECTIVE', width: 400, height: 400,
                     shadows: true, samples: 1});

function wrapAzimuth(a) {
  return a >= -180 && a < 180 ? a : ((((a + 180) % 360) + 360) % 360) - 180;
}

// Merges `partial` into the view (clamped), shows it, and schedules a camera.
function setView(partial) {
  if (partial === null || typeof partial !== 'object') throw new TypeError('setView takes an object');
  const next = {...view};
  for (const [k, v] of Object.entries(partial)) {
    switch (k) {
      case 'azimuth': next.azimuth = wrapAzimuth(num(v, next.azimuth)); break;
      case 'elevation': next.elevation = clamp(num(v, next.elevation), -89, 89); break;
      case 'zoom': next.zoom = clamp(num(v, next.zoom), 0.2, 20); break;
      case 'projection':
        if (!PROJECTIONS.includes(v)) throw new RangeError(`projection must be ${PROJECTIONS.join(' or ')}`);
        next.projection = v;
        break;
      case 'width': case 'height': {
        const n = Math.round(num(v, 0));
        if (n < 1 || n > 8192) throw new RangeError(`${k} must be in 1 .. 8192`);
        next[k] = n;
        break;
      }
      case 'shadows': next.shadows = Boolean(v); break;
      case 'samples': {
        const n = Math.round(num(v, 0));
        if (n < 1 || n > 64) throw new RangeError('samples must be in 1 .. 64');
        next.samples = n;
        break;
      }
      default: throw new RangeError(`setView: unknown field '${k}'`);
    }
  }
  view = normView(next);
  showViewControls();
  sizeViewport();
  cameraChanged();
  return normView(view);
}

function showViewControls() {
  const put = (id, v) => {
    const e = $(id);
    if (document.activeElement !== e) e.value = v;
  };
  put('azimuth', fmtValue(Math.round(view.azimuth * 10) / 10));
  put('elevation', fmtValue(Math.round(view.elevation * 10) / 10));
  put('zoom', fmtValue(Math.round(view.zoom * 1000) / 1000));
  $('size').value = SIZES.includes(view.width) && view.width === view.height ? String(view.width) : '';
  $('samples').value = String(view.samples);
  $('projection').value = view.projection;
  $('shadows').checked = view.shadows;
}

function sizeViewport() {
  const vp = $('viewport');
  vp.style.width = `${view.width}px`;
  vp.style.aspectRatio = `${view.width} / ${view.height}`;
  $('stage').style.width = `${view.width + 2}px`;
}

function setupViewControls() {
  const onNumber = (id, field) => $(id).addEventListener('change', (e) => {
    const v = Number(e.target.value);
    if (e.target.value === '' || !Number.isFinite(v)) {
      setStatus(`${field}: '${e.target.value}' is not a number`, 'error');
      showViewControls();
      return;
    }
    setView({[field]: v});
    e.target.value = fmtValue(view[field]);   // as clamped
  });
  onNumber('azimuth', 'azimuth');
  onNumber('elevation', 'elevation');
  onNumber('zoom', 'zoom');
  $('size').addEventListener('change', (e) => {
    const n = Number(e.target.value);
    setView({width: n, height: n});
  });
  $('samples').addEventListener('change', (e) => setView({samples: Number(e.target.value)}));
  $('projection').addEventListener('change', (e) => setView({projection: e.target.value}));
  $('shadows').addEventListener('change', (e) => setView({shadows: e.target.checked}));
  $('reset-camera').addEventListener('click', () => setView(defaultCamera()));
}

// Drag orbits, the wheel zooms, keys do both.
function setupViewport() {
  const vp = $('viewport');
  let drag = null;
  vp.addEventListener('pointerdown', (e) => {
    if (e.button !== 0) return;
    vp.setPointerCapture(e.pointerId);
    drag = {id: e.pointerId, x: e.clientX, y: e.clientY};
    vp.classList.add('dragging');
    vp.focus({preventScroll: true});
    e.preventDefault();
  });
  vp.addEventListener('pointermove', (e) => {
    if (!drag || e.pointerId !== drag.id) return;
    const dx = e.clientX - drag.x;
    const dy = e.clientY - drag.y;
    drag.x = e.clientX;
    drag.y = e.clientY;
    if (dx === 0 && dy === 0) return;
    setView({azimuth: view.azimuth + dx * 0.4, elevation: view.elevation - dy * 0.4});
  });
  const end = (e) => {
    if (!drag || e.pointerId !== drag.id) return;
    drag = null;
    vp.classList.remove('dragging');
    if (vp.hasPointerCapture(e.pointerId)) vp.releasePointerCapture(e.pointerId);
  };
  vp.addEventListener('pointerup', end);
  vp.addEventListener('pointercancel', end);
  vp.addEventListener('lostpointercapture', end);
  vp.addEventListener('wheel', (e) => {
    e.preventDefault();
    const dy = e.deltaMode === 1 ? e.deltaY * 33 : e.deltaMode === 2 ? e.deltaY * 400 : e.deltaY;
    setView({zoom: view.zoom * 1.1 ** (-dy / 100)});
  }, {passive: false});
  vp.addEventListener('keydown', (e) => {
    const step = e.shiftKey ? 15 : 5;
    const keys = {
      ArrowLeft: () => ({azimuth: view.azimuth - step}),
      ArrowRight: () => ({azimuth: view.azimuth + step}),
      ArrowUp: () => ({elevation: view.elevation + step}),
      ArrowDown: () => ({elevation: view.elevation - step}),
      '+': () => ({zoom: view.zoom * 1.1}),
      '=': () => ({zoom: view.zoom * 1.1}),
      '-': () => ({zoom: view.zoom / 1.1}),
      '0': () => defaultCamera(),
      Home: () => defaultCamera(),
    };
    const f = keys[e.key];
    if (!f) return;
    e.preventDefault();
    setView(f());
  });
  vp.addEventListener('dragstart', (e) => e.preventDefault());
}

// ------------------------------------------------------------ session

// The session in force, or null. Fields:
//   id, volume, preset: what was opened
//   live: the gateway holds it (false once ended, expired or closed)
//   abort: AbortController of its polls and requests
//   seqViews: Map seq -> the View that seq's frames are rendered with
//   sentAt: Map seq -> performance.now() when that request was sent
//   kinds: Map seq -> what that request was, for its errors
//   lastSent: the last View sent; viewDirty: the page's view is newer
//   pendingClass: a classification to send; inFlight: a POST is out
//   ready: the last SessionReady; readySeq: its seq
let session = null;

// Frames shown: what window.transtickViewer tells.
let framesShown = 0;
let lastFrame = null;
let frameUrl = null;
const fullTimes = [];   // performance.now() of recent full frames, for frames/s

function closeSession(reason) {
  const s = session;
  if (!s) return;
  session = null;
  s.live = false;
  s.abort.abort();
  if (s.id) {
    // Best effort: the gateway closes idle sessions itself.
    apiFetch('DELETE', `api/sessions/${encodeURIComponent(s.id)}`).catch(() => {});
  }
  if (reason) setStatus(reason);
}

function presetOf(value) {
  const [name, mode] = value.split('|');
  return {name, mode};
}

let lastOpened = null;

async function openSession(volume, presetValue) {
  closeSession();
  lastOpened = {volume, presetValue};
  showReopen(false);
  const {name, mode} = presetOf(presetValue);
  const info = presets.find((p) => p.name === name);
  const preset = {name};
  // The root's default mode is surfaces when the preset has materials.
  if (mode === 'DVR' && (!info || info.surfaces)) preset.mode = 'DVR';
  const first = normView(view);
  const s = {
    id: null, volume, presetValue, live: false, abort: new AbortController(),
    seqViews: new Map(), sentAt: new Map(), kinds: new Map(), lastSent: first, viewDirty: false,
    pendingClass: null, inFlight: null, ready: null, readySeq: null, openAt: performance.now(),
    openView: first, appliedSeq: null,
  };
  session = s;
  const url = new URL(location.href);
  url.searchParams.set('volume', volume);
  url.searchParams.set('preset', name);
  if (preset.mode) url.searchParams.set('mode', preset.mode.toLowerCase());
  else url.searchParams.delete('mode');
  history.replaceState(null, '', url);
  setStatus(`Opening ${volume} with ${name}${preset.mode ? ` (${preset.mode.toLowerCase()})` : ''}…`);
  $('open').disabled = true;
  let reply;
  try {
    reply = await api('POST', 'api/sessions',
                      {dataset: {volume, preset, views: [first]}, preview: PREVIEW}, s.abort.signal);
  } catch (e) {
    if (s !== session) return;
    session = null;
    setStatus(`Could not open ${volume}: ${e.message}${authHint(e)}`, 'error');
    showReopen(true);
    return;
  } finally {
    $('open').disabled = false;
  }
  if (s !== session) {
    // Another open or a close came first: this one is not wanted.
    apiFetch('DELETE', `api/sessions/${encodeURIComponent(reply.session)}`).catch(() => {});
    return;
  }
  s.id = String(reply.session);
  s.live = true;
  setStatus(`Session ${s.id} open: ${volume}. Rendering…`, 'ok');
  if (reply.ready) onReady(s, {seq: null, ready: reply.ready});
  pollEvents(s);
  if (s.viewDirty) cameraChanged();
}

// The view was changed: send it with the next animation frame.
let rafPending = false;
function cameraChanged() {
  if (session) session.viewDirty = true;
  if (!rafPending) {
    rafPending = true;
    requestAnimationFrame(() => {
      rafPending = false;
      flushRequests();
    });
  }
}

// Sends what is waiting (the newest camera and/or a classification) in one
// POST. One POST is out at a time, so the gateway numbers them in the order
// they were made, and a burst of cameras while one is out becomes one.
async function flushRequests() {
  const s = session;
  if (!s || !s.live || s.inFlight) return;
  const body = {};
  if (s.viewDirty && JSON.stringify(view) !== JSON.stringify(s.lastSent)) body.view = normView(view);
  s.viewDirty = false;
  if (s.pendingClass) body[s.pendingClass.kind] = s.pendingClass.value;
  const isClass = Boolean(s.pendingClass);
  s.pendingClass = null;
  if (Object.keys(body).length === 0) return;
  // The frames of this request are rendered with its camera, or (for a
  // classification alone) with the last camera sent.
  const frameView = body.view || s.lastSent;
  s.lastSent = frameView;
  const sentAt = performance.now();
  s.inFlight = {view: frameView, sentAt, camera: Boolean(body.view)};
  try {
    const r = await api('POST', `api/sessions/${encodeURIComponent(s.id)}`, body, s.abort.signal);
    const seq = Number(r.seq);
    s.seqViews.set(seq, frameView);
    s.sentAt.set(seq, sentAt);
    s.kinds.set(seq, body.view && isClass ? 'Camera and classification' : isClass ? 'Classification' : 'Camera');
    if (isClass) s.appliedSeq = seq;
    pruneSeqs(s);
  } catch (e) {
    if (s !== session || e.name === 'AbortError') return;
    if (e.status === 404) {
      sessionGone(s, 'The session expired (the gateway closes a session idle for a minute).');
      return;
    }
    setStatus(`${isClass ? 'Classification' : 'Camera'} not sent: ${e.message}`, 'error');
    if (isClass) markClassDirty(true);
  } finally {
    if (s.inFlight && s.inFlight.sentAt === sentAt) s.inFlight = null;
  }
  if (s === session && (s.viewDirty || s.pendingClass)) cameraChanged();
}

function pruneSeqs(s) {
  if (s.seqViews.size <= 256) return;
  const keys = [...s.seqViews.keys()].sort((a, b) => a - b);
  for (const k of keys.slice(0, keys.length - 128)) {
    s.seqViews.delete(k);
    s.sentAt.delete(k);
    s.kinds.delete(k);
  }
}

// The View that seq's frames were asked with.
function viewOfSeq(s, seq) {
  if (s.seqViews.has(seq)) return s.seqViews.get(seq);
  // The answer to the POST that is out may not have come back yet.
  if (s.inFlight) return s.inFlight.view;
  let best = null;
  for (const [k, v] of s.seqViews) if (k <= seq && (best === null || k > best.k)) best = {k, v};
  return best ? best.v : s.lastSent;
}

function sessionGone(s, why) {
  if (s !== session) return;
  s.live = false;
  s.abort.abort();
  session = null;
  setStatus(`${why} Reopen to go on.`, 'error');
  showReopen(true);
}

// Long-polls the session's events until it ends or another replaces it.
async function pollEvents(s) {
  let after = 0;
  let backoff = 500;
  while (s === session && s.live) {
    let r;
    try {
      r = await apiFetch('GET', `api/sessions/${encodeURIComponent(s.id)}/events?after=${after}&wait=${EVENTS_WAIT_S}`,
                         undefined, s.abort.signal);
    } catch (e) {
      if (s !== session || e.name === 'AbortError') return;
      setStatus(`Events: network error (${e.message}); retrying in ${(backoff / 1000).toFixed(1)} s`, 'error');
      await sleep(backoff);
      backoff = Math.min(backoff * 2, 10000);
      continue;
    }
    if (s !== session) return;
    if (r.status === 404) {
      sessionGone(s, 'The session expired or the gateway restarted.');
      return;
    }
    if (!r.ok) {
      const e = await errorOf(r);
      setStatus(`Events: ${e.message}; retrying in ${(backoff / 1000).toFixed(1)} s`, 'error');
      await sleep(backoff);
      backoff = Math.min(backoff * 2, 10000);
      continue;
    }
    let batch;
    try {
      batch = parseEvents(await r.arrayBuffer());
    } catch (e) {
      if (s !== session || e.name === 'AbortError') return;
      setStatus(`Events: a malformed answer (${e.message}); retrying`, 'error');
      await sleep(backoff);
      backoff = Math.min(backoff * 2, 10000);
      continue;
    }
    if (backoff > 500 && s.live) setStatus('Events: connected again.', 'ok');
    backoff = 500;
    after = num(batch.next, after);
    await onEvents(s, batch.events || []);
  }
}

// The events answer: u32 LE length L, L bytes of JSON, then the PNGs, each
// event's "png": [offset, length] counting from the first byte after the JSON.
function parseEvents(buf) {
  const bytes = new Uint8Array(buf);
  if (bytes.length < 4) throw new Error(`${bytes.length} bytes, fewer than the length`);
  const len = new DataView(buf).getUint32(0, true);
  if (4 + len > bytes.length) throw new Error(`the JSON length ${len} runs past the ${bytes.length} bytes`);
  const msg = JSON.parse(new TextDecoder().decode(bytes.subarray(4, 4 + len)));
  const base = 4 + len;
  for (const ev of msg.events || []) {
    if (!ev.png || ev.png.length === 0) continue;
    const [off, n] = ev.png.map(Number);
    if (!(off >= 0 && n > 0 && base + off + n <= bytes.length)) {
      throw new Error(`event ${ev.index}: png [${off}, ${n}] is outside the answer`);
    }
    ev.pngBytes = bytes.slice(base + off, base + off + n);
  }
  return msg;
}

async function onEvents(s, events) {
  // Only the last frame of a batch is worth decoding.
  let lastFrameIndex = -1;
  events.forEach((ev, i) => {
    if (ev.kind === 'frame') lastFrameIndex = i;
  });
  for (let i = 0; i < events.length; i++) {
    if (s !== session) return;
    const ev = events[i];
    switch (ev.kind) {
      case 'ready': onReady(s, ev); break;
      case 'frame': if (i === lastFrameIndex) await onFrame(s, ev); break;
      case 'error': onError(s, ev); break;
      case 'end':
        sessionGone(s, ev.error ? `The session ended: ${ev.error}.` : 'The session ended.');
        return;
      default: setStatus(`Event ${ev.index}: unknown kind '${ev.kind}'`, 'warn');
    }
  }
}

function onError(s, ev) {
  const seq = num(ev.seq);
  const kind = s.kinds.get(seq) || (s.inFlight ? 'The request' : seq === s.readySeq ? 'Opening' : `Request ${seq}`);
  const what = `${kind} refused`;
  setStatus(`${what}: ${ev.error}`, 'error');
  if (seq === s.appliedSeq) markClassDirty(true);
}

function onReady(s, ev) {
  const ready = ev.ready || {};
  if (ev.seq !== null && ev.seq !== undefined) {
    const seq = Number(ev.seq);
    if (s.readySeq === null && !s.seqViews.has(seq)) {
      // The first ready answers the open request: its frames have the first view.
      s.seqViews.set(seq, s.openView);
      s.sentAt.set(seq, s.openAt);
    }
    s.readySeq = seq;
  }
  s.ready = ready;
  showVolumeInfo(s, ready);
  showWarnings(ready.warnings || [], 'classification');
  // A new ready brings the classification in force; an edit the user has
  // not applied yet is kept unless this ready answers the Apply.
  if (!editor.dirty || (ev.seq !== null && Number(ev.seq) === s.appliedSeq)) loadEditor(ready);
  else drawHistogram();
  if (ev.seq !== null && Number(ev.seq) === s.appliedSeq) setStatus('Classification applied.', 'ok');
}

async function onFrame(s, ev) {
  const seq = num(ev.seq);
  const frameView = viewOfSeq(s, seq);
  const url = URL.createObjectURL(new Blob([ev.pngBytes], {type: 'image/png'}));
  // Decoded off screen first, so the image on screen changes at once.
  const decoded = new Image();
  decoded.src = url;
  try {
    await decoded.decode();
  } catch (e) {
    URL.revokeObjectURL(url);
    if (s === session) setStatus(`Frame ${seq}: the PNG could not be decoded (${e.message})`, 'error');
    return;
  }
  if (s !== session) {
    URL.revokeObjectURL(url);
    return;
  }
  const img = $('frame');
  img.src = url;
  if (frameUrl) URL.revokeObjectURL(frameUrl);
  frameUrl = url;
  const preview = Boolean(ev.preview);
  $('placeholder').hidden = true;
  $('badge').hidden = !preview;
  img.alt = `${s.volume}, azimuth ${frameView.azimuth.toFixed(1)}°, elevation ${frameView.elevation.toFixed(1)}°${preview ? ' (preview)' : ''}`;
  lastFrame = {seq, preview, view: normView(frameView), png: ev.pngBytes};
  $('stat-seq').textContent = String(seq);
  if (preview) return;
  framesShown++;
  const now = performance.now();
  // frames/s over the recent run of frames: a pause of 2 s starts a new run.
  if (fullTimes.length && now - fullTimes[fullTimes.length - 1] > 2000) fullTimes.length = 0;
  fullTimes.push(now);
  while (fullTimes.length > 20) fullTimes.shift();
  const stats = ev.stats || {};
  $('stat-frame-ms').textContent = fmtMs(num(stats.frame_ms, NaN));
  $('stat-fps').textContent = fullTimes.length > 1
    ? ((fullTimes.length - 1) / ((now - fullTimes[0]) / 1000)).toFixed(1) : '–';
  // The request's answer (its seq) may come after its frame.
  const sent = s.sentAt.has(seq) ? s.sentAt.get(seq)
    : s.inFlight && !s.seqViews.has(seq) ? s.inFlight.sentAt : undefined;
  if (sent !== undefined) {
    $('stat-latency').textContent = fmtMs(now - sent);
    s.sentAt.delete(seq);
  }
  $('stat-frames').textContent = String(framesShown);
  if (s.firstFull === undefined) {
    s.firstFull = now - s.openAt;
    setStatus(`${s.volume}: first frame in ${fmtMs(s.firstFull)}. Drag to orbit, wheel to zoom.`, 'ok');
  }
  showWarnings(stats.warnings || (s.ready && s.ready.warnings) || [], 'frame');
  showWorkers(stats);
}

function showWarnings(warnings, source) {
  const ul = $('warnings');
  ul.replaceChildren(...warnings.map((w) => el('li', {text: w, title: `from the ${source}`})));
}

function showVolumeInfo(s, ready) {
  const dims = (ready.dims || []).map(Number);
  const spacing = (ready.spacing || []).map(Number);
  const range = (ready.range || []).map(Number);
  const parts = [s.volume];
  if (dims.length === 3) parts.push(`${dims.join(' × ')} voxels`);
  if (spacing.length === 3) parts.push(`spacing ${spacing.map((x) => fmtValue(x)).join(' ')}`);
  if (range.length === 2) parts.push(`values ${fmtValue(range[0])} … ${fmtValue(range[1])}`);
  const info = $('volume-info');
  info.textContent = parts.join(' · ');
  info.dataset.dims = dims.join(',');
}

function showWorkers(stats) {
  const tbody = $('workers').tBodies[0];
  const workers = stats.workers || [];
  tbody.replaceChildren(...workers.map((w) => {
    const active = num(w.active_ms);
    const elapsed = num(w.elapsed_ms);
    const slab = (w.slab || []).map(Number);
    const frac = elapsed > 0 ? clamp(active / elapsed, 0, 1) : 0;
    const bar = el('span', {class: 'bar', title: `${(frac * 100).toFixed(0)}% active`},
                   el('span', {class: 'fill'}));
    bar.firstChild.style.width = `${(frac * 100).toFixed(1)}%`;
    const tr = el('tr', {},
      el('td', {text: w.id || '', title: w.address || ''}),
      el('td', {class: 'num', text: String(num(w.ring))}),
      el('td', {class: 'num', text: slab.length === 2 ? `[${slab[0]}, ${slab[1]})` : '–'}),
      el('td', {class: 'num', text: active.toFixed(1)}),
      el('td', {class: 'num', text: elapsed.toFixed(1)}),
      el('td', {}, bar),
      el('td', {class: 'num', text: fmtCount(w.rays_traced), title: String(w.rays_traced || 0)}),
      el('td', {class: 'num', text: fmtCount(w.rays_sent), title: String(w.rays_sent || 0)}),
      el('td', {class: 'num', text: fmtCount(w.rays_received), title: String(w.rays_received || 0)}));
    if (slab.length === 2) {
      tr.dataset.slabBegin = String(slab[0]);
      tr.dataset.slabEnd = String(slab[1]);
    }
    return tr;
  }));
  const imb = stats.active_imbalance;
  $('imbalance').textContent = workers.length
    ? `active imbalance ${num(imb, NaN).toFixed(3)} (max / mean active time) · frame ${fmtMs(num(stats.frame_ms, NaN))}`
      + ` · ${stats.rings ? `${stats.rings} ring${stats.rings > 1 ? 's' : ''}` : ''}`
    : 'no per-worker statistics in this frame';
}

// ------------------------------------------------------------ classification editor

// The editor's state: a copy of the classification in force, edited in place.
const editor = {
  mode: null,        // 'SURFACES' or 'DVR'
  materials: null,   // MaterialSet being edited
  transfer: null,    // TransferFunction being edited
  selected: -1,      // material or point index
  dirty: false,
  histogram: [],
  range: [0, 1],
};

function loadEditor(ready) {
  editor.mode = ready.mode === 'DVR' || (ready.transfer && !ready.materials) ? 'DVR' : 'SURFACES';
  editor.materials = clone(ready.materials) || {materials: []};
  if (!editor.materials.materials) editor.materials.materials = [];
  editor.transfer = clone(ready.transfer) || {points: []};
  if (!editor.transfer.points) editor.transfer.points = [];
  for (const p of editor.transfer.points) p.value = num(p.value);
  editor.histogram = (ready.histogram || []).map(Number);
  const r = (ready.range || [0, 1]).map(Number);
  editor.range = r.length === 2 && r[1] >= r[0] ? r : [0, 1];
  if (editor.selected >= itemCount()) editor.selected = -1;
  $('class-mode').textContent = editor.mode === 'DVR' ? 'dvr' : 'surfaces';
  // Shadow rays are a surfaces-mode thing: the root ignores them in dvr.
  $('shadows').disabled = editor.mode === 'DVR';
  $('class-help').textContent = editor.mode === 'DVR'
    ? 'Drag a point; click to add one; right-click or Delete removes it. Then Apply.'
    : 'Drag a band\u2019s edge or edit the numbers; then Apply.';
  $('class-add').disabled = false;
  $('class-add').textContent = editor.mode === 'DVR' ? 'Add point' : 'Add material';
  markClassDirty(false);
  renderEditorTable();
  drawHistogram();
}

const itemCount = () => (editor.mode === 'DVR' ? editor.transfer.points.length
  : editor.mode === 'SURFACES' ? editor.materials.materials.length : 0);

function markClassDirty(dirty) {
  editor.dirty = dirty;
  $('class-apply').disabled = !dirty || !editor.mode;
  $('class-revert').disabled = !dirty;
}

function edited() {
  markClassDirty(true);
  drawHistogram();
}

// The value axis: the volume's range, widened to show classification
// edges a little beyond it.
function domain() {
  let [lo, hi] = editor.range;
  if (!(hi > lo)) {
    lo -= 0.5;
    hi += 0.5;
  }
  const ext = (hi - lo) * 0.25;
  const vals = editor.mode === 'DVR' ? editor.transfer.points.map((p) => num(p.value))
    : editor.mode === 'SURFACES' ? editor.materials.materials.flatMap((m) => [num(m.min), num(m.max)])
    : [];
  let dlo = lo;
  let dhi = hi;
  for (const v of vals) {
    if (v < dlo) dlo = Math.max(v, lo - ext);
    if (v > dhi) dhi = Math.min(v, hi + ext);
  }
  return [dlo, dhi];
}

// A step for dragged values: about a thousandth of the axis, a power of 10.
function valueStep() {
  const [lo, hi] = domain();
  return 10 ** Math.floor(Math.log10((hi - lo) / 1000));
}

const roundTo = (x, step) => Number((Math.round(x / step) * step).toPrecision(12));

function canvasGeom() {
  const c = $('histogram');
  const w = c.clientWidth || 360;
  const h = c.clientHeight || 150;
  const pad = {l: 6, r: 6, t: 8, b: 30};
  const [lo, hi] = domain();
  const X = (v) => pad.l + ((v - lo) / (hi - lo)) * (w - pad.l - pad.r);
  const V = (x) => lo + ((x - pad.l) / (w - pad.l - pad.r)) * (hi - lo);
  const plotH = h - pad.t - pad.b;
  const Y = (a) => pad.t + (1 - a) * plotH;
  const A = (y) => 1 - (y - pad.t) / plotH;
  return {c, w, h, pad, lo, hi, X, V, Y, A, plotH};
}

function drawHistogram() {
  const g = canvasGeom();
  const {c, w, h, pad, X, Y} = g;
  const dpr = window.devicePixelRatio || 1;
  if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) {
    c.width = Math.round(w * dpr);
    c.height = Math.round(h * dpr);
  }
  const ctx = c.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  ctx.fillStyle = '#111417';
  ctx.fillRect(0, 0, w, h);
  const hist = editor.histogram;
  const [rlo, rhi] = editor.range;
  if (editor.mode === 'SURFACES') drawMaterials(ctx, g, 'fill');
  if (hist.length > 0) {
    // Log scale: a bin's bar is log(1 + count) over log(1 + the largest count).
    const top = Math.log1p(Math.max(...hist));
    const bw = (rhi - rlo) / hist.length;
    ctx.fillStyle = '#5b6672';
    hist.forEach((n, i) => {
      if (n <= 0 || top <= 0) return;
      const x0 = X(rlo + i * bw);
      const x1 = Math.max(X(rlo + (i + 1) * bw), x0 + 1);
      const y = Y(Math.log1p(n) / top);
      ctx.fillRect(x0, y, x1 - x0 - (x1 - x0 > 3 ? 0.5 : 0), pad.t + g.plotH - y);
    });
  }
  if (editor.mode === 'DVR') drawTransfer(ctx, g);
  else if (editor.mode === 'SURFACES') drawMaterials(ctx, g, 'edges');
  // The axis: the volume's range, and the axis ends when wider.
  ctx.fillStyle = '#9aa5b1';
  ctx.font = '11px system-ui, sans-serif';
  ctx.textBaseline = 'top';
  const yAxis = h - pad.b + 14;
  ctx.textAlign = 'left';
  ctx.fillText(fmtValue(g.lo), pad.l, yAxis);
  ctx.textAlign = 'right';
  ctx.fillText(fmtValue(g.hi), w - pad.r, yAxis);
  if (hist.length > 0) {
    ctx.strokeStyle = '#9aa5b1';
    ctx.beginPath();
    ctx.moveTo(X(rlo), h - pad.b + 1.5);
    ctx.lineTo(X(rhi), h - pad.b + 1.5);
    ctx.stroke();
    ctx.textAlign = 'center';
    ctx.fillText('values (histogram: log scale)', w / 2, yAxis);
  }
}

// In two passes: the bands' fill under the histogram, their edges and names over it.
function drawMaterials(ctx, g, pass) {
  const {pad, h, X, lo, hi} = g;
  const mats = editor.materials.materials;
  // The first listed wins where intervals overlap: draw it last, on top.
  for (let i = mats.length - 1; i >= 0; i--) {
    const m = mats[i];
    const a = clamp(num(m.min), lo, hi);
    const b = clamp(num(m.max), lo, hi);
    if (!(b > a)) continue;
    const x0 = X(a);
    const x1 = X(b);
    const color = m.color || [1, 1, 1];
    const op = m.opacity === undefined ? 1 : num(m.opacity);
    if (pass === 'fill') {
      ctx.fillStyle = cssRgb(color, 0.15 + 0.25 * op);
      ctx.fillRect(x0, pad.t, x1 - x0, h - pad.t - pad.b);
      continue;
    }
    ctx.strokeStyle = cssRgb(color, 1);
    ctx.lineWidth = i === editor.selected ? 3 : 1.5;
    ctx.beginPath();
    ctx.moveTo(x0, pad.t);
    ctx.lineTo(x0, h - pad.b);
    ctx.moveTo(x1, pad.t);
    ctx.lineTo(x1, h - pad.b);
    ctx.stroke();
    ctx.fillStyle = cssRgb(color, 1);
    ctx.fillRect(x0, h - pad.b - 6, x1 - x0, 6);
    ctx.fillStyle = '#e8edf2';
    ctx.font = '11px system-ui, sans-serif';
    ctx.textAlign = 'left';
    ctx.textBaseline = 'top';
    ctx.fillText(m.name || `material ${i + 1}`, x0 + 3, pad.t + 2 + 13 * (i % 3), Math.max(10, x1 - x0 - 4));
  }
  ctx.lineWidth = 1;
}

// The transfer function's colour and opacity at `v` (piecewise linear; the
// end colours hold beyond the ends).
function transferAt(v) {
  const pts = editor.transfer.points;
  if (pts.length === 0) return [0, 0, 0, 0];
  if (v <= pts[0].value) return pts[0].rgba.map(Number);
  for (let i = 1; i < pts.length; i++) {
    if (v <= pts[i].value) {
      const a = pts[i - 1];
      const b = pts[i];
      const t = (v - a.value) / (b.value - a.value);
      return a.rgba.map((x, k) => num(x) + t * (num(b.rgba[k]) - num(x)));
    }
  }
  return pts[pts.length - 1].rgba.map(Number);
}

function drawTransfer(ctx, g) {
  const {pad, w, h, X, Y, lo, hi} = g;
  const pts = editor.transfer.points;
  // The opacity axis: faint lines at 0.5 and 1.
  ctx.strokeStyle = 'rgba(232, 237, 242, 0.15)';
  ctx.setLineDash([3, 3]);
  ctx.beginPath();
  for (const a of [0.5, 1]) {
    ctx.moveTo(pad.l, Y(a) + 0.5);
    ctx.lineTo(w - pad.r, Y(a) + 0.5);
  }
  ctx.stroke();
  ctx.setLineDash([]);
  ctx.fillStyle = '#9aa5b1';
  ctx.font = '10px system-ui, sans-serif';
  ctx.textAlign = 'right';
  ctx.textBaseline = 'top';
  ctx.fillText('opacity 1', w - pad.r - 2, Y(1) + 2);
  if (pts.length === 0) return;
  // Colour strip under the plot, and the curve filled with the colours.
  const grad = ctx.createLinearGradient(pad.l, 0, w - pad.r, 0);
  const stops = [lo, ...pts.map((p) => p.value).filter((v) => v > lo && v < hi), hi];
  for (const v of stops) {
    const rgba = transferAt(v);
    grad.addColorStop(clamp((v - lo) / (hi - lo), 0, 1), cssRgb(rgba, 1));
  }
  ctx.fillStyle = grad;
  ctx.fillRect(pad.l, h - pad.b + 4, w - pad.l - pad.r, 8);
  ctx.save();
  ctx.beginPath();
  ctx.moveTo(X(lo), Y(0));
  ctx.lineTo(X(lo), Y(clamp(num(transferAt(lo)[3]), 0, 1)));
  for (const p of pts) {
    if (p.value > lo && p.value < hi) ctx.lineTo(X(p.value), Y(clamp(num(p.rgba[3]), 0, 1)));
  }
  ctx.lineTo(X(hi), Y(clamp(num(transferAt(hi)[3]), 0, 1)));
  ctx.lineTo(X(hi), Y(0));
  ctx.closePath();
  ctx.globalAlpha = 0.35;
  ctx.fill();
  ctx.globalAlpha = 1;
  ctx.strokeStyle = '#e8edf2';
  ctx.lineWidth = 1.5;
  ctx.stroke();
  ctx.restore();
  pts.forEach((p, i) => {
    const x = X(clamp(p.value, lo, hi));
    const y = Y(clamp(num(p.rgba[3]), 0, 1));
    ctx.beginPath();
    ctx.arc(x, y, i === editor.selected ? 6 : 4.5, 0, 2 * Math.PI);
    ctx.fillStyle = cssRgb(p.rgba, 1);
    ctx.fill();
    ctx.lineWidth = i === editor.selected ? 2.5 : 1.5;
    ctx.strokeStyle = i === editor.selected ? '#ffd24a' : '#e8edf2';
    ctx.stroke();
  });
  ctx.lineWidth = 1;
}

function numberInput(value, label, onChange, attrs = {}) {
  const input = el('input', {type: 'number', step: 'any', value: fmtValue(num(value)), 'aria-label': label, ...attrs});
  input.addEventListener('change', () => {
    const v = Number(input.value);
    if (input.value === '' || !Number.isFinite(v)) {
      input.setAttribute('aria-invalid', 'true');
      setStatus(`${label}: '${input.value}' is not a number`, 'error');
      return;
    }
    input.removeAttribute('aria-invalid');
    onChange(v, input);
  });
  return input;
}

function colorInput(rgb, label, onChange) {
  const input = el('input', {type: 'color', value: rgbHex(rgb || [1, 1, 1]), 'aria-label': label});
  input.addEventListener('input', () => onChange(hexRgb(input.value)));
  return input;
}

function selectItem(i) {
  editor.selected = i;
  const rows = $('class-editor').querySelectorAll('tbody tr');
  rows.forEach((r, k) => r.classList.toggle('selected', k === i));
  drawHistogram();
}

function renderEditorTable() {
  const box = $('class-editor');
  if (editor.mode === 'DVR') box.replaceChildren(transferTable());
  else if (editor.mode === 'SURFACES') box.replaceChildren(materialsTable());
  else box.replaceChildren();
  selectItem(editor.selected);
}

function materialsTable() {
  const mats = editor.materials.materials;
  const rows = mats.map((m, i) => {
    const n = `material ${i + 1}`;
    const name = el('input', {type: 'text', value: m.name || '', 'aria-label': `${n} name`, size: 8});
    name.addEventListener('change', () => {
      m.name = name.value;
      edited();
    });
    const opacity = m.opacity === undefined ? 1 : num(m.opacity);
    const tr = el('tr', {onfocusin: () => selectItem(i), onclick: () => selectItem(i)},
      el('td', {}, name),
      el('td', {}, numberInput(m.min, `${n} min`, (v) => { m.min = v; edited(); }, {class: 'mat-min'})),
      el('td', {}, numberInput(m.max, `${n} max`, (v) => { m.max = v; edited(); }, {class: 'mat-max'})),
      el('td', {}, colorInput(m.color, `${n} colour`, (c) => { m.color = c; edited(); })),
      el('td', {}, numberInput(opacity, `${n} opacity`, (v, input) => {
        m.opacity = clamp(v, 0, 1);
        input.value = fmtValue(m.opacity);
        edited();
      }, {min: 0, max: 1, step: 0.05, class: 'mat-opacity'})),
      el('td', {}, el('button', {type: 'button', class: 'icon', 'aria-label': `delete ${n}`, title: 'Delete',
                                 onclick: (e) => { e.stopPropagation(); deleteItem(i); }}, '×')));
    return tr;
  });
  return el('table', {class: 'editor-table'},
    el('thead', {}, el('tr', {}, ...['name', 'min', 'max', 'colour', 'opacity', ''].map((t) => el('th', {scope: 'col', text: t})))),
    el('tbody', {}, ...rows));
}

function transferTable() {
  const pts = editor.transfer.points;
  const rows = pts.map((p, i) => {
    const n = `point ${i + 1}`;
    const tr = el('tr', {onfocusin: () => selectItem(i), onclick: () => selectItem(i)},
      el('td', {}, numberInput(p.value, `${n} value`, (v, input) => {
        const lo = i > 0 ? pts[i - 1].value : -Infinity;
        const hi = i < pts.length - 1 ? pts[i + 1].value : Infinity;
        if (!(v > lo && v < hi)) {
          setStatus(`${n}: values must strictly increase (between ${fmtValue(lo)} and ${fmtValue(hi)})`, 'error');
          input.value = fmtValue(p.value);
          return;
        }
        p.value = v;
        edited();
      }, {class: 'pt-value'})),
      el('td', {}, numberInput(p.rgba[3], `${n} opacity`, (v, input) => {
        p.rgba[3] = clamp(v, 0, 1);
        input.value = fmtValue(p.rgba[3]);
        edited();
      }, {min: 0, max: 1, step: 0.01, class: 'pt-alpha'})),
      el('td', {}, colorInput(p.rgba, `${n} colour`, (c) => {
        p.rgba = [...c, p.rgba[3]];
        edited();
      })),
      el('td', {}, el('button', {type: 'button', class: 'icon', 'aria-label': `delete ${n}`, title: 'Delete',
                                 onclick: (e) => { e.stopPropagation(); deleteItem(i); }}, '×')));
    return tr;
  });
  return el('table', {class: 'editor-table'},
    el('thead', {}, el('tr', {}, ...['value', 'opacity', 'colour', ''].map((t) => el('th', {scope: 'col', text: t})))),
    el('tbody', {}, ...rows));
}

function deleteItem(i) {
  if (editor.mode === 'DVR') {
    if (editor.transfer.points.length <= 2) {
      setStatus('A transfer function keeps at least two points.', 'warn');
      return;
    }
    editor.transfer.points.splice(i, 1);
  } else {
    if (editor.materials.materials.length <= 1) {
      setStatus('Surfaces mode keeps at least one material.', 'warn');
      return;
    }
    editor.materials.materials.splice(i, 1);
  }
  editor.selected = Math.min(i, itemCount() - 1);
  markClassDirty(true);
  renderEditorTable();
}

function addPoint(value, alpha) {
  const pts = editor.transfer.points;
  if (pts.some((p) => p.value === value)) return -1;
  const rgba = transferAt(value);
  rgba[3] = Number(clamp(alpha, 0, 1).toFixed(3));
  const p = {value, rgba: rgba.map((x) => Number(x.toFixed(4)))};
  let i = pts.findIndex((q) => q.value > value);
  if (i < 0) i = pts.length;
  pts.splice(i, 0, p);
  return i;
}

function addItem() {
  const [lo, hi] = editor.range;
  if (editor.mode === 'DVR') {
    // Halfway along the widest gap between points.
    const pts = editor.transfer.points;
    let v = (lo + hi) / 2;
    if (pts.length >= 2) {
      let best = 0;
      for (let k = 1; k < pts.length; k++) {
        if (pts[k].value - pts[k - 1].value > best) {
          best = pts[k].value - pts[k - 1].value;
          v = (pts[k].value + pts[k - 1].value) / 2;
        }
      }
    }
    const i = addPoint(roundTo(v, valueStep()), num(transferAt(v)[3]));
    if (i >= 0) editor.selected = i;
  } else {
    const mats = editor.materials.materials;
    const width = (hi - lo) || 1;
    mats.push({name: `material ${mats.length + 1}`, min: roundTo(lo + 0.4 * width, valueStep()),
               max: roundTo(lo + 0.6 * width, valueStep()), color: [0.8, 0.5, 0.3], opacity: 1});
    editor.selected = mats.length - 1;
  }
  markClassDirty(true);
  renderEditorTable();
}

function applyClassification() {
  const s = session;
  if (!s || !s.live) {
    setStatus('No session to apply the classification to: open one first.', 'error');
    return;
  }
  if (editor.mode === 'DVR') {
    s.pendingClass = {kind: 'transfer', value: clone(editor.transfer)};
  } else {
    for (const m of editor.materials.materials) {
      if (!(num(m.max) > num(m.min))) {
        setStatus(`Material '${m.name}': min must be below max.`, 'error');
        return;
      }
    }
    s.pendingClass = {kind: 'materials', value: clone(editor.materials)};
  }
  markClassDirty(false);
  setStatus('Applying the classification…');
  cameraChanged();
}

function setupEditor() {
  const c = $('histogram');
  let drag = null;
  const pos = (e) => {
    const r = c.getBoundingClientRect();
    return {x: e.clientX - r.left, y: e.clientY - r.top};
  };
  // The item under (x, y): a transfer point, or a material's edge.
  const hit = (x, y) => {
    const g = canvasGeom();
    if (editor.mode === 'DVR') {
      let best = null;
      editor.transfer.points.forEach((p, i) => {
        const d = Math.hypot(g.X(clamp(p.value, g.lo, g.hi)) - x, g.Y(clamp(num(p.rgba[3]), 0, 1)) - y);
        if (d <= 8 && (!best || d < best.d)) best = {i, d};
      });
      return best && {kind: 'point', i: best.i};
    }
    let best = null;
    editor.materials.materials.forEach((m, i) => {
      for (const edge of ['min', 'max']) {
        const d = Math.abs(g.X(clamp(num(m[edge]), g.lo, g.hi)) - x);
        const better = !best || d < best.d || (d === best.d && i === editor.selected);
        if (d <= 6 && better) best = {i, d, edge};
      }
    });
    if (best) return {kind: 'edge', i: best.i, edge: best.edge};
    const v = g.V(x);
    const i = editor.materials.materials.findIndex((m) => v >= num(m.min) && v < num(m.max));
    return i >= 0 ? {kind: 'band', i} : null;
  };
  c.addEventListener('pointerdown', (e) => {
    if (e.button !== 0 || !editor.mode) return;
    const {x, y} = pos(e);
    const h = hit(x, y);
    c.focus({preventScroll: true});
    if (!h) {
      if (editor.mode === 'DVR') {
        const g = canvasGeom();
        const i = addPoint(roundTo(g.V(x), valueStep()), clamp(g.A(y), 0, 1));
        if (i >= 0) {
          editor.selected = i;
          markClassDirty(true);
          renderEditorTable();
          drag = {kind: 'point', i, id: e.pointerId};
          c.setPointerCapture(e.pointerId);
        }
      }
      return;
    }
    selectItem(h.i);
    if (h.kind === 'band') return;
    drag = {...h, id: e.pointerId};
    c.setPointerCapture(e.pointerId);
    e.preventDefault();
  });
  c.addEventListener('pointermove', (e) => {
    const {x, y} = pos(e);
    if (!drag) {
      const h = editor.mode ? hit(x, y) : null;
      c.style.cursor = !h ? (editor.mode === 'DVR' ? 'crosshair' : 'default')
        : h.kind === 'edge' ? 'ew-resize' : h.kind === 'point' ? 'move' : 'pointer';
      return;
    }
    if (e.pointerId !== drag.id) return;
    const g = canvasGeom();
    const step = valueStep();
    const v = roundTo(g.V(clamp(x, g.pad.l, g.w - g.pad.r)), step);
    if (drag.kind === 'point') {
      const pts = editor.transfer.points;
      const p = pts[drag.i];
      const lo = drag.i > 0 ? pts[drag.i - 1].value : -Infinity;
      const hi = drag.i < pts.length - 1 ? pts[drag.i + 1].value : Infinity;
      if (v > lo && v < hi) p.value = v;
      p.rgba[3] = Number(clamp(g.A(y), 0, 1).toFixed(3));
    } else {
      const m = editor.materials.materials[drag.i];
      if (drag.edge === 'min' && v < num(m.max)) m.min = v;
      if (drag.edge === 'max' && v > num(m.min)) m.max = v;
    }
    drag.moved = true;
    markClassDirty(true);
    drawHistogram();
    syncEditorRow(drag.i);
  });
  const end = (e) => {
    if (!drag || e.pointerId !== drag.id) return;
    drag = null;
    if (c.hasPointerCapture(e.pointerId)) c.releasePointerCapture(e.pointerId);
  };
  c.addEventListener('pointerup', end);
  c.addEventListener('pointercancel', end);
  c.addEventListener('contextmenu', (e) => {
    if (editor.mode !== 'DVR') return;
    e.preventDefault();
    const {x, y} = pos(e);
    const h = hit(x, y);
    if (h && h.kind === 'point') deleteItem(h.i);
  });
  c.addEventListener('keydown', (e) => {
    if (!editor.mode) return;
    const n = itemCount();
    if (e.key === 'Tab' || n === 0) return;
    if (e.key === 'Delete' || e.key === 'Backspace') {
      if (editor.selected >= 0) deleteItem(editor.selected);
    } else if (e.key === '[' || e.key === ']') {
      selectItem(((editor.selected < 0 ? 0 : editor.selected) + (e.key === ']' ? 1 : n - 1)) % n);
    } else {
      return;
    }
    e.preventDefault();
  });
  $('class-add').addEventListener('click', addItem);
  $('class-apply').addEventListener('click', applyClassification);
  $('class-revert').addEventListener('click', () => {
    if (session && session.ready) loadEditor(session.ready);
    setStatus('Classification edits reverted.');
  });
  new ResizeObserver(() => drawHistogram()).observe(c);
}

// After a drag on the canvas: the row's numbers follow.
function syncEditorRow(i) {
  const row = $('class-editor').querySelectorAll('tbody tr')[i];
  if (!row) return;
  const set = (cls, v) => {
    const input = row.querySelector(cls);
    if (input) input.value = fmtValue(num(v));
  };
  if (editor.mode === 'DVR') {
    const p = editor.transfer.points[i];
    set('.pt-value', p.value);
    set('.pt-alpha', p.rgba[3]);
  } else {
    const m = editor.materials.materials[i];
    set('.mat-min', m.min);
    set('.mat-max', m.max);
  }
}

// ------------------------------------------------------------ volumes and presets

let presets = [];

async function loadVolumes() {
  let reply;
  try {
    reply = await api('GET', 'api/volumes');
  } catch (e) {
    setStatus(`Could not list the volumes: ${e.message}${authHint(e)}`, 'error');
    return false;
  }
  const vsel = $('volume');
  const keep = vsel.value;
  const vols = reply.volumes || [];
  // A study's series are DIR#UID, several with one DIR: shown by DIR (a
  // directory named with a '#' holding one series keeps its whole name).
  const studies = new Map();
  for (const v of vols) {
    const hash = v.series ? v.path.lastIndexOf('#') : -1;
    if (hash > 0) studies.set(v.path.slice(0, hash), (studies.get(v.path.slice(0, hash)) || 0) + 1);
  }
  vsel.replaceChildren(...vols.map((v) => volumeOption(v, studies)));
  if (vols.length === 0) vsel.append(el('option', {value: '', text: '(no volumes in the data directory)'}));
  if (reply.truncated) setStatus('The data directory holds more than the listing shows (it was truncated).', 'warn');
  if (keep) vsel.value = keep;
  presets = reply.presets || [];
  const psel = $('preset');
  const pkeep = psel.value;
  const options = [];
  for (const p of presets) {
    if (p.surfaces) options.push(el('option', {value: `${p.name}|SURFACES`, text: `${p.name}: surfaces`, title: p.description || ''}));
    if (p.dvr) options.push(el('option', {value: `${p.name}|DVR`, text: `${p.name}: dvr`, title: p.description || ''}));
  }
  psel.replaceChildren(...options);
  if (pkeep) psel.value = pkeep;
  if (!psel.value) psel.value = presets.some((p) => p.name === 'grey') ? 'grey|DVR' : (options[0] && options[0].value) || '';
  return true;
}

// A volume of the listing as an option: a DICOM series with what its
// headers say (one of a study, whose directory `studies` counts more than
// once, is shown by its directory; the path that opens it, DIR#UID, is the
// value and the tooltip), and one the root says would not open, disabled,
// with why.
function volumeOption(v, studies) {
  const hash = v.series ? v.path.lastIndexOf('#') : -1;
  const study = hash > 0 && studies.get(v.path.slice(0, hash)) > 1;
  const shown = study ? v.path.slice(0, hash) : v.path;
  let text = shown;
  if (v.series) text += v.description ? `  [DICOM: ${v.description}]` : '  [DICOM series]';
  text += `  (${fmtBytes(num(v.bytes))})`;
  const o = el('option', {value: v.path, text, title: v.path});
  if (v.error) {
    const why = v.error.length > 160 ? `${v.error.slice(0, 157)}...` : v.error;
    o.textContent = `${text}  cannot open: ${why}`;
    o.title = `${v.path}: ${v.error}`;
    o.disabled = true;
  }
  return o;
}

function fmtBytes(n) {
  if (n >= 1 << 30) return `${(n / (1 << 30)).toFixed(1)} GiB`;
  if (n >= 1 << 20) return `${(n / (1 << 20)).toFixed(1)} MiB`;
  if (n >= 1 << 10) return `${(n / (1 << 10)).toFixed(0)} KiB`;
  return `${n} B`;
}

// The preset option for a URL's preset and mode.
function presetOption(name, mode) {
  const p = presets.find((q) => q.name === name);
  if (!p) return null;
  const m = (mode || '').toUpperCase();
  if (m === 'DVR' && p.dvr) return `${name}|DVR`;
  if (m === 'SURFACES' && p.surfaces) return `${name}|SURFACES`;
  if (m) return null;
  return p.surfaces ? `${name}|SURFACES` : `${name}|DVR`;
}

function setupOpen() {
  $('open-form').addEventListener('submit', (e) => {
    e.preventDefault();
    const volume = $('volume').value;
    const preset = $('preset').value;
    if (!volume || !preset) {
      setStatus('Pick a volume and a classification first.', 'error');
      return;
    }
    openSession(volume, preset);
  });
  // Reopen opens again what was open last, whatever the pickers say now.
  $('reopen').addEventListener('click', () => {
    if (lastOpened) openSession(lastOpened.volume, lastOpened.presetValue);
  });
  window.addEventListener('pagehide', () => {
    if (session && session.id) {
      // keepalive lets the DELETE outlive the page.
      fetch(`api/sessions/${encodeURIComponent(session.id)}`,
            {method: 'DELETE', headers: headers(false), keepalive: true, credentials: 'omit'}).catch(() => {});
    }
  });
}

// ------------------------------------------------------------ jobs

let statusBusy = false;
let statusError = '';

async function pollStatus() {
  if (statusBusy) return;
  statusBusy = true;
  try {
    const reply = await api('GET', 'api/status');
    showJobs(reply);
    if (statusError) setStatus('Cluster status: answering again.', 'ok');
    statusError = '';
  } catch (e) {
    // Said once, not every 2 s.
    if (e.message !== statusError) setStatus(`Cluster status: ${e.message}`, 'error');
    statusError = e.message;
  } finally {
    statusBusy = false;
  }
}

function showJobs(reply) {
  const workers = reply.workers || [];
  const rings = num(reply.rings);
  $('cluster-info').textContent = `${workers.length} worker${workers.length === 1 ? '' : 's'}, ${rings} ring${rings === 1 ? '' : 's'}`;
  const jobs = [...(reply.jobs || [])].sort((a, b) => num(b.submitted_unix) - num(a.submitted_unix));
  const tbody = $('jobs').tBodies[0];
  if (jobs.length === 0) {
    tbody.replaceChildren(el('tr', {}, el('td', {colspan: 5, class: 'hint', text: 'no jobs'})));
    return;
  }
  tbody.replaceChildren(...jobs.map((j) => {
    const state = j.state || 'JOB_STATE_UNSPECIFIED';
    const total = num(j.frames_total);
    const done = num(j.frames_done);
    const cancellable = state === 'QUEUED' || state === 'RUNNING';
    const cancel = cancellable
      ? el('button', {type: 'button', class: 'small', 'aria-label': `cancel job ${j.name || j.job_id}`,
                      onclick: (e) => cancelJob(j, e.target)}, 'Cancel')
      : '';
    const progress = el('progress', {max: String(Math.max(total, 1)), value: String(done),
                                     'aria-label': `${done} of ${total} frames`});
    const tr = el('tr', {'data-job': j.job_id, 'data-state': state},
      el('td', {text: j.name || j.job_id, title: `${j.job_id}${j.error ? `: ${j.error}` : ''}`}),
      el('td', {text: j.owner || '', title: j.owner || ''}),
      el('td', {class: `state ${state.toLowerCase()}`, text: state.toLowerCase(), title: j.error || ''}),
      el('td', {class: 'progress-cell'}, progress, el('span', {class: 'num', text: ` ${done}/${total}`})),
      el('td', {}, cancel));
    return tr;
  }));
}

async function cancelJob(job, button) {
  button.disabled = true;
  try {
    const r = await api('POST', `api/jobs/${encodeURIComponent(job.job_id)}/cancel`, {});
    setStatus(r.cancelled ? `Job ${job.name || job.job_id} cancelled.` : `Job ${job.name || job.job_id} had already ended.`, 'ok');
  } catch (e) {
    setStatus(`Cancel ${job.name || job.job_id}: ${e.message}`, 'error');
    button.disabled = false;
  }
  pollStatus();
}

// ------------------------------------------------------------ start

window.transtickViewer = {
  get view() { return normView(view); },
  get frames() { return framesShown; },
  get lastFrame() {
    return lastFrame && {seq: lastFrame.seq, preview: lastFrame.preview, view: normView(lastFrame.view),
                         png: lastFrame.png};
  },
  setView,
};

async function start() {
  setupAuth();
  setupViewControls();
  setupViewport();
  setupEditor();
  setupOpen();
  showViewControls();
  sizeViewport();
  drawHistogram();
  try {
    const config = await api('GET', 'api/config');
    if (config.auth && !token()) needToken('This gateway needs a token.');
    if (config.version) document.title = `transtick viewer · ${config.version}`;
  } catch (e) {
    setStatus(`Could not read the gateway's configuration: ${e.message}`, 'error');
  }
  pollStatus();
  setInterval(pollStatus, STATUS_PERIOD_MS);
  if (!(await loadVolumes())) return;
  const q = new URLSearchParams(location.search);
  const volume = q.get('volume');
  if (!volume) {
    setStatus('Pick a volume and a classification, then Open.');
    return;
  }
  const vsel = $('volume');
  if (![...vsel.options].some((o) => o.value === volume)) {
    // Not in the listing (it may be truncated): the root decides.
    vsel.append(el('option', {value: volume, text: volume}));
  }
  vsel.value = volume;
  const presetName = q.get('preset');
  let option = presetName ? presetOption(presetName, q.get('mode')) : $('preset').value;
  if (!option) {
    setStatus(`Unknown preset '${presetName}'${q.get('mode') ? ` for mode ${q.get('mode')}` : ''}; pick one.`, 'error');
    return;
  }
  $('preset').value = option;
  openSession(volume, option);
}

start();
