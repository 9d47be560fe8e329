// labkit live view: the run's live stream (Server-Sent Events) drawn as SVG. No library, nothing remote.
'use strict';
(function () {
  const token = new URLSearchParams(location.search).get('token') || '';
  const COLORS = {body: '#1e88e5', hip: '#8e24aa', knee: '#f4511e', tray: '#00897b'};
  const S = {start: null, points: [], events: [], drive: false, end: null, status: null, statusAt: 0,
             conn: 'connecting', stopSent: '', latency: [], openedAt: 0, speeds: []};
  window.__labkit = S;                 // for tests and the curious
  const $ = (id) => document.getElementById(id);
  const NS = 'http://www.w3.org/2000/svg';

  // -- numbers ---------------------------------------------------------------------------------
  const fin = (x) => typeof x === 'number' && isFinite(x);
  const mag = (z) => Math.hypot(z[0] || 0, z[1] || 0);
  const db = (z) => { const m = mag(z); return m > 0 ? 20 * Math.log10(m) : NaN; };
  const deg = (z) => Math.atan2(z[1] || 0, z[0] || 0) * 180 / Math.PI;
  const dur = (s) => { if (!fin(s)) return '-'; s = Math.max(0, Math.round(s));
    const h = Math.floor(s / 3600), m = Math.floor(s / 60) % 60, x = s % 60;
    return (h ? h + ':' + String(m).padStart(2, '0') : m) + ':' + String(x).padStart(2, '0'); };
  const clock = (t) => new Date(t * 1000).toTimeString().slice(0, 8);

  // -- SVG plots -------------------------------------------------------------------------------
  function el(name, attrs, text) {
    const e = document.createElementNS(NS, name);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (text !== undefined) e.textContent = text;
    return e;
  }
  function niceTicks(lo, hi, n) {
    const span = hi - lo || 1, step0 = span / n, p = Math.pow(10, Math.floor(Math.log10(step0)));
    const step = [1, 2, 5, 10].map((m) => m * p).find((s) => s >= step0) || p * 10;
    const out = [];
    for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(+v.toPrecision(12));
    return out;
  }
  // grid at 1..9 x 10^e; labels at 1, 2, 5 (and 3 when the plot spans under a decade and a half)
  function logTicks(lo, hi) {
    const out = [], label = hi / lo < 30 ? [1, 2, 3, 5] : [1, 2, 5];
    for (let e = Math.floor(Math.log10(lo)); e <= Math.ceil(Math.log10(hi)); e++)
      for (let m = 1; m < 10; m++) { const v = m * Math.pow(10, e); if (v >= lo && v <= hi) out.push([v, label.includes(m)]); }
    return out;
  }
  // series: [{name, color, pts: [[x, y]], dash, hollow}]; o: {logx, ymin, ymax, hlines: [{y, label}]}
  function plot(svg, series, o) {
    while (svg.firstChild) svg.removeChild(svg.firstChild);
    const W = svg.clientWidth || 600, H = svg.clientHeight || 230, L = 52, R = 10, T = 20, B = 26;   // legend above T
    svg.setAttribute('viewBox', '0 0 ' + W + ' ' + H);
    const xs = [], ys = [];
    series.forEach((s) => s.pts.forEach((p) => { if (fin(p[0]) && fin(p[1]) && (!o.logx || p[0] > 0)) {
      xs.push(p[0]); ys.push(p[1]); } }));
    series.forEach((s) => (s.bars || []).forEach((b) => { if (fin(b[1]) && fin(b[2])) ys.push(b[1], b[2]); }));
    (o.hlines || []).forEach((h) => ys.push(h.y));
    if (!xs.length) { svg.appendChild(el('text', {x: W / 2, y: H / 2, 'text-anchor': 'middle'}, 'waiting for points')); return; }
    let x0 = Math.min(...xs), x1 = Math.max(...xs), y0 = o.ymin !== undefined ? o.ymin : Math.min(...ys),
      y1 = o.ymax !== undefined ? o.ymax : Math.max(...ys);
    if (o.logx) { if (x1 / x0 < 1.5) { x0 /= 1.25; x1 *= 1.25; } } else if (x1 - x0 < 1e-9) { x0 -= 1; x1 += 1; }
    if (y1 - y0 < 1e-9) { y0 -= 1; y1 += 1; }
    const pad = (y1 - y0) * 0.06; y0 -= pad; y1 += pad;
    const fx = o.logx ? (x) => L + (Math.log10(x) - Math.log10(x0)) / (Math.log10(x1) - Math.log10(x0)) * (W - L - R)
      : (x) => L + (x - x0) / (x1 - x0) * (W - L - R);
    const fy = (y) => T + (y1 - y) / (y1 - y0) * (H - T - B);
    (o.logx ? logTicks(x0, x1) : niceTicks(x0, x1, 6).map((v) => [v, true])).forEach(([v, lab]) => {
      svg.appendChild(el('line', {x1: fx(v), x2: fx(v), y1: T, y2: H - B, class: 'grid'}));
      if (lab) svg.appendChild(el('text', {x: fx(v), y: H - B + 14, 'text-anchor': 'middle'}, v >= 1000 ? (v / 1000) + 'k' : String(v)));
    });
    niceTicks(y0, y1, 5).forEach((v) => {
      svg.appendChild(el('line', {x1: L, x2: W - R, y1: fy(v), y2: fy(v), class: 'grid'}));
      svg.appendChild(el('text', {x: L - 4, y: fy(v) + 4, 'text-anchor': 'end'}, String(v)));
    });
    svg.appendChild(el('line', {x1: L, x2: L, y1: T, y2: H - B, class: 'axis'}));
    svg.appendChild(el('line', {x1: L, x2: W - R, y1: H - B, y2: H - B, class: 'axis'}));
    svg.appendChild(el('text', {x: W - R, y: H - 2, 'text-anchor': 'end'}, o.xlabel || 'frequency (Hz)'));
    (o.hlines || []).forEach((h) => {
      svg.appendChild(el('line', {x1: L, x2: W - R, y1: fy(h.y), y2: fy(h.y), class: 'thr'}));
      svg.appendChild(el('text', {x: W - R - 2, y: fy(h.y) + 13, 'text-anchor': 'end'}, h.label));
    });
    let lx = L + 8;
    series.forEach((s) => {
      const pts = s.pts.filter((p) => fin(p[0]) && fin(p[1]) && (!o.logx || p[0] > 0)).sort((a, b) => a[0] - b[0]);
      if (pts.length > 1) svg.appendChild(el('polyline', {points: pts.map((p) => fx(p[0]) + ',' + fy(p[1])).join(' '),
        fill: 'none', stroke: s.color, 'stroke-width': 1.5, 'stroke-dasharray': s.dash ? '4 3' : 'none'}));
      (s.bars || []).forEach((b) => { if (fin(b[0]) && fin(b[1]) && fin(b[2])) svg.appendChild(el('line',
        {x1: fx(b[0]), x2: fx(b[0]), y1: fy(b[1]), y2: fy(b[2]), stroke: s.color, 'stroke-width': 1.5, class: 'ci'})); });
      if (pts.length < 400) pts.forEach((p) => svg.appendChild(el('circle', {cx: fx(p[0]), cy: fy(p[1]), r: 2.6,
        fill: s.hollow ? '#fff' : s.color, stroke: s.color, class: 'pt'})));
      svg.appendChild(el('text', {x: lx, y: 12}, s.name)).style.fill = s.color;   // CSSOM: allowed by the CSP
      lx += 9 * s.name.length + 14;
    });
  }

  // -- the records -----------------------------------------------------------------------------
  function onRecord(r) {
    if (r.t === 'start') { S.start = r; S.end = null; S.stopSent = ''; }
    else if (r.t === 'point') {
      S.points.push(r);
      if (S.openedAt && r.time > S.openedAt) S.latency.push(Date.now() / 1000 - r.time);   // live, not replayed
    }
    else if (r.t === 'event') { S.events.push(r); if (typeof r.drive === 'boolean') S.drive = r.drive; }
    else if (r.t === 'end') { S.end = r; }
    else if (r.t === 'hb') { S.busy = r.busy_s; }        // the run's time in its current step
    schedule();
  }
  let pending = false;
  function schedule() { if (!pending) { pending = true; requestAnimationFrame(() => { pending = false; draw(); }); } }

  function series(value) {
    const by = {};
    S.points.forEach((p) => {
      if (p.status !== 'ok') return;
      const loc = p.location || '?';
      const s = by[loc] || (by[loc] = {name: loc, color: COLORS[loc] || '#546e7a', pts: []});
      if (Array.isArray(p.freq_hz)) p.freq_hz.forEach((f, i) => s.pts.push([f, value(p, i)]));
      else s.pts.push([p.freq_hz, value(p, -1)]);
    });
    return Object.values(by);
  }
  const frfOf = (p, i) => { const z = p.transmissibility || p.frf; return i < 0 ? z : [z[0][i], z[1][i]]; };
  const qOf = (p, i) => (i < 0 ? p.quality : p.quality[i]);

  function draw() {
    const st = S.start || {}, last = S.points[S.points.length - 1], shaker = st.kind === 'run_shaker';
    $('file').textContent = st.file || 'run';
    $('k').textContent = last ? last.k : (st.points_done || 0);
    $('n').textContent = st.points_planned || '?';
    $('freq').textContent = last && fin(last.freq_hz) ? last.freq_hz.toFixed(2) + ' Hz' : '-';
    const now = S.status ? S.status.now + (Date.now() - S.statusAt) / 1000 : Date.now() / 1000;
    const ended = !!S.end;
    $('elapsed').textContent = st.time ? dur((ended ? S.end.time : now) - st.time) : '-';
    $('remaining').textContent = ended ? '0:00' : (last ? dur(last.remaining_s - (now - last.time)) : (fin(st.est_s) ? '~' + dur(st.est_s) : '-'));
    const drive = $('drive'); drive.textContent = S.drive ? 'DRIVE ON' : 'DRIVE OFF'; drive.className = 'cell lamp ' + (S.drive ? 'on' : 'off');
    const age = S.status && fin(S.status.stream_age_s) ? S.status.stream_age_s + (Date.now() - S.statusAt) / 1000 : NaN;
    $('hb').textContent = ended ? 'run ended' : (fin(age) ? age.toFixed(1) + ' s ago' : '-') +
      (!ended && S.busy > 10 ? ' (one step for ' + S.busy.toFixed(0) + ' s)' : '');
    const state = $('state');
    if (ended) { state.textContent = 'ended: ' + S.end.status + ' (exit ' + S.end.exit + ')';
      state.className = 'cell ' + (S.end.exit === 0 ? 'ended' : 'failed'); }
    else { state.textContent = S.conn === 'open' ? 'running' : S.conn; state.className = 'cell'; }
    // the way back when the run does not answer
    const banner = $('banner'), off = 'labkit off ' + (st.config || 'CONFIG');
    let warn = '';
    if (!ended && S.status && !S.status.running && S.start) warn = 'Run not responding: its process is gone without an end record; the drive may still be on. Turn it off: ';
    else if (!ended && fin(age) && age > (S.status.stale_s || 5)) warn = 'Run not responding: no heartbeat for ' + age.toFixed(0) + ' s. If it does not recover, turn the drive off: ';
    else if (S.conn === 'lost' && !ended) warn = 'The view server does not answer (labkit view stopped?). The run is not affected; if in doubt: ';
    banner.hidden = !warn;
    if (warn) { banner.textContent = warn; banner.appendChild(document.createElement('code')).textContent = off; }
    const canStop = !!S.start && !ended && !!S.status && S.status.running;
    $('stop-point').disabled = !canStop; $('stop-now').disabled = !canStop;
    // plots
    $('h-mag').textContent = shaker ? 'transmissibility |T| (dB) against frequency' : '|H| (dB re 1 (mm/s)/V) against frequency, per location';
    $('h-phase').textContent = shaker ? 'phase of T (deg) against frequency' : 'phase of H (deg) against frequency';
    plot($('mag'), series((p, i) => db(frfOf(p, i))), {logx: true});
    plot($('phase'), series((p, i) => deg(frfOf(p, i))), {logx: true});
    const thr = st.quality_min || 0.9;
    plot($('quality'), series(qOf), {logx: true, ymax: 1, hlines: [{y: thr, label: 'threshold ' + thr}]});
    $('shaker').hidden = !shaker;
    if (shaker) {
      const ok = S.points.filter((p) => p.status === 'ok');
      plot($('tray'), [{name: 'measured', color: '#00897b', pts: ok.map((p) => [p.freq_hz, p.tray_amp_um])},
        {name: 'target', color: '#546e7a', hollow: true, dash: true, pts: ok.map((p) => [p.freq_hz, p.tray_amp_request_um])}], {logx: true, ymin: 0});
      plot($('drivev'), [{name: 'drive', color: '#e53935', pts: ok.map((p) => [p.freq_hz, p.drive_vpp])}], {logx: true, ymin: 0});
      const sp = S.speeds.filter((r) => fin(r.speed_mm_s));
      plot($('speed'), [{name: 'speed', color: '#6d4c41', pts: sp.map((r) => [r.freq_hz, r.speed_mm_s]),
        bars: sp.map((r) => [r.freq_hz, r.ci_mm_s[0], r.ci_mm_s[1]])}], {logx: true, ymin: 0});
      const videos = ok.filter((p) => p.video).length, failed = S.speeds.filter((r) => r.error);
      $('speed-note').textContent = (videos ? 'Each point\'s video is tracked by labkit view as it arrives (as labkit track does): ' +
        sp.length + ' of ' + videos + ' tracked.' : 'No video in this run (run.video_s = 0): no speed.') +
        failed.map((r) => ' Point ' + r.k + ' (' + r.video + '): ' + r.error).join('');
    }
    drawRecord(last);
    drawEvents();
    $('stop-result').textContent = S.stopSent;
  }
  function drawRecord(p) {
    ['drive', 'velocity'].forEach((ch) => {
      const pct = p && p.pct_fs ? p.pct_fs[ch] : null, over = !!(p && p.over && p.over[ch]), under = !!(p && p.under && p.under[ch]);
      const bar = $('pct-' + ch);
      bar.style.width = fin(pct) ? Math.min(pct, 100) + '%' : '0';
      bar.className = over ? 'over' : (under ? 'warn' : '');
      $('pct-' + ch + '-t').textContent = fin(pct) ? pct.toFixed(0) + '% FS' : '-';
      $('ov-' + ch).className = 'lamp ' + (over ? 'on' : 'off');
      $('un-' + ch).className = 'lamp ' + (under ? 'warn' : 'off');
    });
    if (!p) return;
    let text = 'point ' + p.k + ' of ' + p.n + ': ' + p.location + (fin(p.freq_hz) ? ' ' + p.freq_hz.toFixed(2) + ' Hz' : '') + ', ' + p.status;
    if (p.reason) text += ' (' + p.reason + ')';
    if (p.status === 'ok' && p.frf && !Array.isArray(p.frf[0])) text += ', |H| ' + db(p.frf).toFixed(1) + ' dB, ' + deg(p.frf).toFixed(1) + ' deg';
    if (fin(p.tray_amp_um)) text += ', tray ' + p.tray_amp_um.toPrecision(3) + ' um';
    if (fin(p.drive_vpp)) text += ', drive ' + p.drive_vpp.toPrecision(3) + ' Vpp' + (fin(p.drive_set_vpp) ? ' (set ' + p.drive_set_vpp.toPrecision(3) + ')' : '');
    if (fin(p.drive_measured_vpp)) text += ' (measured ' + p.drive_measured_vpp.toPrecision(3) + ')';
    if (fin(p.quality)) text += ', quality ' + p.quality.toFixed(3);
    $('last-point').textContent = text;
  }
  let shownEvents = 0;
  function drawEvents() {
    const ol = $('events');
    for (; shownEvents < S.events.length; shownEvents++) {
      const e = S.events[shownEvents], li = document.createElement('li');
      li.textContent = clock(e.time) + '  ' + e.text;
      if (e.drive === true) li.className = 'drive-on'; else if (e.drive === false) li.className = 'drive-off';
      ol.insertBefore(li, ol.firstChild);
    }
  }

  // -- stop ------------------------------------------------------------------------------------
  async function stop(when) {
    $('stop-point').disabled = true; $('stop-now').disabled = true;
    try {
      const r = await fetch('/stop', {method: 'POST', headers: {'Content-Type': 'application/json', 'X-Labkit-Token': token},
        body: JSON.stringify({when: when}), cache: 'no-store'});
      const j = await r.json();
      S.stopSent = j.ok ? j.sent + ': sent to the run (pid ' + j.pid + ')' : 'not sent: ' + j.error;
    } catch (err) { S.stopSent = 'not sent: the view server does not answer'; }
    schedule();
  }

  // -- the stream ------------------------------------------------------------------------------
  function connect() {
    const es = new EventSource('/events?token=' + encodeURIComponent(token));
    es.onopen = () => { S.conn = 'open'; S.openedAt = S.openedAt || Date.now() / 1000; schedule(); };
    es.onmessage = (e) => { try { onRecord(JSON.parse(e.data)); } catch (err) { /* a torn line: skipped */ } };
    es.addEventListener('speed', (e) => { S.speeds.push(JSON.parse(e.data)); schedule(); });
    es.addEventListener('status', (e) => { S.status = JSON.parse(e.data); S.statusAt = Date.now(); S.conn = 'open'; schedule(); });
    es.onerror = () => { S.conn = es.readyState === EventSource.CLOSED ? 'lost' : 'reconnecting'; schedule(); };
  }
  document.addEventListener('DOMContentLoaded', () => {
    $('stop-point').addEventListener('click', () => stop('point'));
    $('stop-now').addEventListener('click', () => stop('now'));
    window.addEventListener('resize', schedule);
    setInterval(schedule, 500);          // ages and times move between records
    connect();
    schedule();
  });
})();
