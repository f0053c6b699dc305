// The workbench page: plain JavaScript over the JSON API (docs/workbench.md), charts by dygraphs.
// One loop at a time: its trends, two models of the ladder (A and B) against the data, the valve
// signature and PV against OP, the findings with an "Add" button each, and the ladder of models
// fitted in this session.
'use strict';

const wb = {
  loops: [],
  loop: null,       // the loop shown (an entry of /api/loops)
  ladder: [],       // its steps
  shown: null,      // model A: the ladder step drawn against the data
  compare: null,    // model B: the step drawn beside it, or null
  compareChoice: 'auto',  // B as chosen: 'auto' (the step before A), 'none' or a step number
  job: null,        // the page's running job id
  charts: {},
  xy: {},           // the phase plots as last drawn: {points, series, message}
  window: null,     // [from, to] zoomed, null: the whole record
  history: [],      // the jobs this page ran, how each ended
  validate: null,   // the held-out share the next jobs ask for, once the split was dragged
  dragShare: null,  // the share under the mouse while the split's edge is dragged
  jobs: [],         // the request bodies of the jobs this page started
  status: null,     // the live recording's status (/api/status)
};
window.wb = wb;  // for the browser test and the curious

const $ = (id) => document.getElementById(id);

function fmt(x, digits = 1) {
  return x === null || x === undefined || !isFinite(x) ? '-' : Number(x).toFixed(digits);
}

// A sample period as engineers write it: 5 ms, 0.5 s, 2 s (fixed decimals would show 5 ms as 0.01 s).
function period(s) {
  if (!(s > 0) || !isFinite(s)) return '-';
  return s < 0.1 ? Number((1000 * s).toPrecision(3)) + ' ms' : Number(s.toPrecision(3)) + ' s';
}

// A time in seconds: whole seconds from 100 s on, else three significant digits.
function seconds(x) {
  if (x === null || x === undefined || !isFinite(x)) return '-';
  return Math.abs(x) >= 100 ? x.toFixed(0) : String(Number(x.toPrecision(3)));
}

function signed(x, digits = 1) {
  if (x === null || x === undefined || !isFinite(x)) return '';
  return (x > 0 ? '+' : '') + Number(x).toFixed(digits);
}

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === 'class') e.className = v;
    else if (k.startsWith('data-')) e.setAttribute(k, v);
    else e[k] = v;
  }
  for (const c of children) e.append(c);
  return e;
}

function showError(text) {
  $('error').textContent = text;
  $('error').hidden = !text;
}

// GET or send JSON; resolves to the parsed body, rejects with the API's error message.
async function api(path, options = {}) {
  const r = await fetch(path, options);
  const body = await r.json().catch(() => ({}));
  if (!r.ok) {
    const err = new Error(body.error || r.status + ' ' + r.statusText);
    err.status = r.status;
    throw err;
  }
  return body;
}

// ---- loops --------------------------------------------------------------------------------

async function loadLoops() {
  wb.loops = (await api('/api/loops')).loops;
  const list = $('loop-list');
  list.replaceChildren();
  for (const l of wb.loops) {
    const li = el('li', { 'data-id': l.id },
      el('div', { class: 'name', textContent: l.name }),
      el('div', { class: 'muted', textContent: loopSize(l) }),
      el('div', { class: 'muted loop-verdict', textContent: l.verdict ? 'verdict: ' + l.verdict : '' }));
    li.onclick = () => selectLoop(l.id);
    list.append(li);
  }
  if (wb.loops.length > 0) selectLoop(wb.loops[0].id);
}


// A long loop name (2_CDU.7040-311_FIC31102) wraps after its separators, not inside a word: the
// text node split after each _ . - with a <wbr> between (its textContent stays the name).
function setBreakable(node, text) {
  node.replaceChildren();
  text.split(/(?<=[_.\-])/).forEach((part, i) => {
    if (i > 0) node.appendChild(document.createElement('wbr'));
    node.appendChild(document.createTextNode(part));
  });
}
// A loop's line in the list: its samples and period (live loops' grow).
function loopSize(l) {
  return l.samples + ' samples, ' + period(l.sample_period_s);
}
function loopInfo(l) {
  return (l.live ? 'recording ' : l.source.split('/').pop() + ': ') + l.samples + ' samples every ' +
    period(l.sample_period_s) + ', t ' + seconds(l.start_s) + ' to ' + seconds(l.end_s) + ' s' +
    (l.start_clock ? ' (from ' + l.start_clock + ')' : '');
}

async function selectLoop(id) {
  wb.loop = wb.loops.find((l) => l.id === id);
  wb.ladder = [];
  wb.shown = null;
  wb.compare = null;
  wb.compareChoice = 'auto';
  wb.window = null;
  for (const li of $('loop-list').children) li.classList.toggle('selected', Number(li.dataset.id) === id);
  $('empty').hidden = true;
  $('view').hidden = false;
  setBreakable($('loop-name'), wb.loop.name);
  $('loop-info').textContent = loopInfo(wb.loop);
  showSplitInfo();
  $('report-link').href = '/api/loops/' + id + '/report';
  showError('');
  if (!wb.loop.live) loadVerdict(id);
  else {  // a live loop's data grows: judged when asked, on the recording so far
    $('verdict').textContent = 'judge the recording so far';
    $('verdict').className = 'verdict ask';
    $('stiction-size').textContent = $('verdict-reason').textContent = '';
  }
  if (wb.loop.samples > 0) await drawTrends();
  await loadLadder();
  await loadDiagnosis();
  // A loop opened for the first time: diagnose the linear model, so that there is a model to
  // compare and findings to act on (a live one when asked: it may hold a few samples yet).
  if (wb.ladder.length === 0 && !wb.job && !wb.loop.live) runJob({ action: 'diagnose' }, 'diagnosing the linear model');
}

$('verdict').onclick = () => {
  if (wb.loop && wb.loop.live && !$('verdict').textContent.startsWith('computing')) loadVerdict(wb.loop.id);
};

async function loadVerdict(id) {
  $('verdict').textContent = 'computing…';
  $('verdict').className = 'verdict';
  $('stiction-size').textContent = '';
  $('verdict-reason').textContent = '';
  try {
    const v = await api('/api/loops/' + id + '/verdict');
    if (!wb.loop || wb.loop.id !== id) return;
    $('verdict').textContent = v.verdict;
    $('verdict').className = 'verdict ' + v.verdict;
    if (v.stiction_percent !== null && v.stiction_percent !== undefined) {
      $('stiction-size').textContent = 'stiction ' + fmt(v.stiction_percent, 2) + ' % of valve travel' +
        (v.slip_jump_percent !== null ? ', slip jump ' + fmt(v.slip_jump_percent, 2) + ' %' : '') +
        (v.stiction_lo_percent !== null ? ' (95 %: ' + fmt(v.stiction_lo_percent, 2) + ' to ' +
          (v.stiction_hi_open ? 'open' : fmt(v.stiction_hi_percent, 2)) + ' %)' : '');
    }
    $('verdict-reason').textContent = (v.verdict_reason || '') + (v.verdict_model ? ' Model: ' + v.verdict_model + '.' : '');
    const li = document.querySelector('#loop-list li[data-id="' + id + '"] .loop-verdict');
    if (li) li.textContent = 'verdict: ' + v.verdict;
  } catch (e) {
    $('verdict').textContent = 'unavailable';
    $('verdict-reason').textContent = e.message;
  }
}

// ---- time charts: decimated on the server, fetched again for the window shown ----------------

function bucketsFor(div) {
  return Math.max(50, Math.min(2000, Math.round(div.clientWidth || 800)));
}

// min/max buckets -> dygraph custom bars [low, middle, high] per signal.
function barRows(s, names) {
  const rows = [];
  for (let k = 0; k < s.t.length; ++k) {
    const row = [(s.t[k] + s.t_end[k]) / 2];
    for (const n of names) {
      const lo = s[n].min[k], hi = s[n].max[k];
      row.push(lo === null || hi === null ? null : [lo, (lo + hi) / 2, hi]);
    }
    rows.push(row);
  }
  return rows;
}

// Whole-record rows outside [from, to], the window's finer rows inside: the x range stays the
// record's, so zooming out and panning keep working.
function merge(coarse, fine, from, to) {
  return coarse.filter((r) => r[0] < from).concat(fine, coarse.filter((r) => r[0] > to));
}

// Model A's split: where its own held-out part starts.
function splitTime() {
  const step = wb.shown;
  if (step && step.estimation_end_s !== null) return step.estimation_end_s;
  return nextSplitTime();
}

// The held-out share the next jobs use: dragged, or the server's (--validate).
function nextShare() {
  return wb.dragShare ?? wb.validate ?? wb.loop.validate;
}

// Where the next jobs' held-out part starts: the last share of the part the models are fitted to
// (after a quiet lead-in), on evenly spaced samples.
function nextSplitTime(share = nextShare()) {
  const l = wb.loop, a = l.analysed_start_s ?? l.start_s;
  return a + (1 - share) * (l.end_s - a);
}

function shareAt(t) {
  const l = wb.loop, a = l.analysed_start_s ?? l.start_s;
  const share = (l.end_s - t) / Math.max(1e-9, l.end_s - a);
  return Math.round(Math.min(0.6, Math.max(0.05, share)) * 1000) / 1000;  // the API's bounds
}

function showSplitInfo() {
  const share = nextShare();
  $('split-info').textContent = 'held out: ' + fmt(100 * share, 1) + ' %' +
    (wb.validate === null && wb.dragShare === null ? ' (the server\'s)' : ' (for the next jobs)');
}

// The trends: the next jobs' split, with its edge marked where it can be dragged.
function shadeNextSplit(canvas, area, g) {
  shadeSplit(canvas, area, g, nextSplitTime());
  const x0 = g.toDomXCoord(nextSplitTime());
  if (x0 <= area.x || x0 >= area.x + area.w) return;
  canvas.fillStyle = wb.dragShare !== null ? '#9a7b1c' : 'rgba(154, 123, 28, 0.6)';
  canvas.fillRect(x0 - 1.5, area.y, 3, area.h);
}

function shadeSplit(canvas, area, g, at = splitTime()) {
  const x0 = g.toDomXCoord(at), left = area.x, right = area.x + area.w;
  if (x0 >= right) return;  // the window shows estimation data only
  canvas.fillStyle = 'rgba(255, 214, 102, 0.22)';
  canvas.fillRect(Math.max(x0, left), area.y, right - Math.max(x0, left), area.h);
  if (x0 <= left) return;
  canvas.fillStyle = '#9a7b1c';
  canvas.font = '11px sans-serif';
  const y = area.y + area.h - 5;  // at the bottom: the legend is above the chart
  canvas.fillText('validation', Math.min(x0 + 4, right - 60), y);
  canvas.fillText('estimation', Math.max(left + 4, x0 - 66), y);
}

// Intervals where the shown model fails (fit --json's where.intervals), shaded red.
function shadeFailures(canvas, area, g) {
  shadeSplit(canvas, area, g);
  for (const iv of (wb.failing || [])) {
    const a = g.toDomXCoord(iv.t_begin_s), b = g.toDomXCoord(iv.t_end_s);
    canvas.fillStyle = 'rgba(214, 69, 65, 0.15)';
    canvas.fillRect(a, area.y, Math.max(2, b - a), area.h);
  }
}

// The legend on a line of its own above the chart, where it hides no data.
function legendFor(div) {
  const l = el('div', { class: 'legend' });
  div.before(l);
  return l;
}

function makeChart(div, labels, colors, options = {}) {
  return new Dygraph(div, [[0].concat(labels.slice(1).map(() => null))], Object.assign({
    labels, colors, customBars: true, xlabel: '', legend: 'always', labelsDiv: legendFor(div),
    strokeWidth: 1.2, fillAlpha: 0.35, axisLabelFontSize: 11, connectSeparatedPoints: false,
    zoomCallback: (from, to) => zoomTo(from, to),
  }, options));
}

function zoomTo(from, to) {
  const whole = from <= wb.loop.start_s + 1e-9 && to >= wb.loop.end_s - 1e-9;
  wb.window = whole ? null : [from, to];
  clearTimeout(wb.zoomTimer);
  wb.zoomTimer = setTimeout(() => { drawTrends(); drawModel(); }, 150);  // drawModel: the phase plots too
}

function windowQuery(div) {
  const q = 'buckets=' + bucketsFor(div);
  return wb.window ? q + '&from=' + wb.window[0] + '&to=' + wb.window[1] : q;
}

// The trend chart's signals of loop l, in its column order.
function trendNames(l) {
  return ['op', 'pv', 'sp'].filter((n) => l.signals.includes(n));
}

async function drawTrends() {
  const l = wb.loop, div = $('trend-chart');
  const names = trendNames(l);
  if (!wb.charts.trend) {
    wb.charts.trend = makeChart(div, ['t (s)'].concat(names.map((n) => n.toUpperCase())),
      ['#1f77b4', '#d62728', '#2ca02c'].slice(0, names.length), { underlayCallback: shadeNextSplit });
    dragSplit(div);
  }
  const id = l.id;
  if (!wb.window || !wb.trendCoarse || wb.trendCoarse.id !== id || wb.trendCoarse.samples !== l.samples) {
    const whole = await api('/api/loops/' + id + '/series?buckets=' + bucketsFor(div));
    wb.trendCoarse = { id, samples: l.samples, rows: barRows(whole, names) };
  }
  let rows = wb.trendCoarse.rows;
  if (wb.window) {
    const s = await api('/api/loops/' + id + '/series?' + windowQuery(div));
    rows = merge(rows, barRows(s, names), wb.window[0], wb.window[1]);
  }
  if (wb.loop.id !== id) return;
  wb.charts.trend.updateOptions({
    file: rows, labels: ['t (s)'].concat(names.map((n) => n.toUpperCase())),
    dateWindow: wb.window || [l.start_s, l.end_s],
  });
}

// Model A drawn against the data and model B beside it (by default the step before A), so
// that a step's gain shows where it is made; then the phase plots of the window.
async function drawModel() {
  const l = wb.loop, step = wb.shown, other = step ? wb.compare : null;
  const name = (tag, s) => tag + ': step ' + s.step + ', ' + s.model;
  const labels = ['t (s)', 'PV measured', step ? name('A', step) : 'PV simulated'].concat(other ? [name('B', other)] : []);
  const colors = ['#d62728', '#222222', '#3a7bd5'].slice(0, labels.length - 1);
  const resLabels = ['t (s)', 'residual A'].concat(other ? ['residual B'] : []);
  const resColors = ['#7b4fa0', '#3a7bd5'].slice(0, resLabels.length - 1);
  if (!wb.charts.fit) {
    wb.charts.fit = makeChart($('fit-chart'), labels, colors, { underlayCallback: shadeFailures });
    wb.charts.residual = makeChart($('residual-chart'), resLabels, resColors,
      { underlayCallback: shadeSplit });
  }
  $('model-name').textContent = step ? 'step ' + step.step + ', ' + step.model : 'no model yet';
  $('compare-name').textContent = other ? '(blue: step ' + other.step + ', ' + other.model + ')' : '';
  showComparison();
  drawPhasePlots();
  if (!step) {
    drawMeasuredPv();
    wb.charts.residual.updateOptions({ file: [[0, null]], labels: resLabels.slice(0, 2), colors: resColors.slice(0, 1) });
    return;
  }
  const base = (n) => '/api/loops/' + l.id + '/models/' + n;
  const key = l.id + '/' + step.step + '/' + (other ? other.step : '-');
  if (!wb.simCoarse || wb.simCoarse.key !== key) {
    const q = '/simulation?buckets=' + bucketsFor($('fit-chart'));
    const [whole, old, model] = await Promise.all([api(base(step.step) + q),
      other ? api(base(other.step) + q) : null, api(base(step.step))]);
    if (wb.loop.id !== l.id || wb.shown !== step || wb.compare !== other) return;  // chosen again
    wb.failing = model.where ? model.where.intervals : [];
    wb.simCoarse = { key, fit: fitRows(whole, old), res: residualRows(whole, old) };
  }
  let fit = wb.simCoarse.fit, res = wb.simCoarse.res;
  if (wb.window) {
    try {
      const q = '/simulation?' + windowQuery($('fit-chart'));
      const [s, old] = await Promise.all([api(base(step.step) + q), other ? api(base(other.step) + q) : null]);
      fit = merge(fit, fitRows(s, old), wb.window[0], wb.window[1]);
      res = merge(res, residualRows(s, old), wb.window[0], wb.window[1]);
    } catch (e) {
      // A window before the analysed part (a lead-in left out) holds no model output.
    }
  }
  if (wb.loop.id !== l.id || wb.shown !== step || wb.compare !== other) return;
  const dw = wb.window || [l.start_s, l.end_s];
  wb.charts.fit.updateOptions({ file: fit, labels, colors, dateWindow: dw });
  wb.charts.residual.updateOptions({ file: res, labels: resLabels, colors: resColors, dateWindow: dw });
  wb.charts.trend.updateOptions({});  // the split may have moved
}

// No model yet: the model's panel shows the measured PV alone, what a model will be fitted to,
// from the trends' rows ([t, [lo, mean, hi]]) as last read (no request of its own).
function drawMeasuredPv() {
  const l = wb.loop, k = trendNames(l).indexOf('pv');
  const rows = k >= 0 && wb.trendCoarse && wb.trendCoarse.id === l.id
    ? wb.trendCoarse.rows.map((r) => [r[0], r[k + 1]]) : [[0, null]];
  wb.charts.fit.updateOptions({ file: rows, labels: ['t (s)', 'PV measured'], colors: ['#d62728'],
    dateWindow: wb.window || [l.start_s, l.end_s] });
}

// Measured and simulated PV, and model B's simulated PV when given (same buckets).
function fitRows(s, old) {
  const rows = barRows(s, ['pv', 'pv_sim']);
  if (old) {
    const o = barRows(old, ['pv_sim']);
    rows.forEach((r, k) => r.push(o[k] ? o[k][1] : null));
  }
  return rows;
}

function residualRows(s, old) {
  const rows = barRows(s, ['residual']);
  if (old) {
    const o = barRows(old, ['residual']);
    rows.forEach((r, k) => r.push(o[k] ? o[k][1] : null));
  }
  return rows;
}

// Models A and B side by side: their fitness on the estimation and the held-out part.
function showComparison() {
  const body = $('compare-table').tBodies[0];
  body.replaceChildren();
  const a = wb.shown, b = wb.compare;
  const row = (tag, s) => el('tr', { 'data-step': s.step, 'data-tag': tag,
    'data-estimation': s.fitness_percent ?? '', 'data-validation': s.validation_fitness_percent ?? '' },
  el('td', { class: 'tag' }, el('span', { class: 'key key-' + tag.toLowerCase() }), tag),
  el('td', { class: 'model', textContent: 'step ' + s.step + ': ' + s.model }),
  el('td', { class: 'num', textContent: fmt(s.fitness_percent) + ' %' }),
  el('td', { class: 'num', textContent: fmt(s.validation_fitness_percent) + ' %' }));
  if (!a) {
    body.append(el('tr', {}, el('td', { colSpan: 4, class: 'muted', textContent: 'No model yet.' })));
    return;
  }
  body.append(row('A', a));
  if (!b) return;
  body.append(row('B', b));
  const diff = (x, y) => (x === null || y === null ? null : x - y);
  const de = diff(a.fitness_percent, b.fitness_percent), dv = diff(a.validation_fitness_percent, b.validation_fitness_percent);
  const cls = (d) => 'num ' + (d > 0 ? 'up' : d < 0 ? 'down' : '');
  body.append(el('tr', { class: 'difference' }, el('td', { class: 'tag', textContent: 'A \u2212 B' }), el('td', {}),
    el('td', { class: cls(de), textContent: signed(de) }), el('td', { class: cls(dv), textContent: signed(dv) })));
}

// B as chosen: the step before A by default, none, or a step of the ladder other than A.
function resolveCompare() {
  const a = wb.shown, c = wb.compareChoice;
  if (typeof c === 'number' && a && c !== a.step && c < wb.ladder.length) {
    wb.compare = wb.ladder[c];
    return;
  }
  if (c !== 'none') wb.compareChoice = 'auto';
  wb.compare = wb.compareChoice === 'auto' && a && a.step > 0 ? wb.ladder[a.step - 1] : null;
}

// The two pickers above the chart: A any step, B the step before A, none, or another step.
function fillPickers() {
  const a = $('model-a'), b = $('model-b');
  const option = (value, text) => el('option', { value: String(value), textContent: text });
  a.replaceChildren(...wb.ladder.map((s) => option(s.step, 'step ' + s.step + ': ' + s.model)));
  a.value = wb.shown ? String(wb.shown.step) : '';
  b.replaceChildren(option('auto', 'the step before A'), option('none', 'none'),
    ...wb.ladder.filter((s) => !wb.shown || s.step !== wb.shown.step)
      .map((s) => option(s.step, 'step ' + s.step + ': ' + s.model)));
  b.value = String(wb.compareChoice);
  a.disabled = b.disabled = wb.ladder.length === 0;
}

// Shows step n as model A (a ladder row clicked, or picked).
function showStep(n) {
  wb.shown = wb.ladder[n];
  wb.followLast = n === wb.ladder.length - 1;
  loadLadder();
}

$('model-a').onchange = (ev) => showStep(Number(ev.target.value));
$('model-b').onchange = (ev) => {
  const v = ev.target.value;
  wb.compareChoice = v === 'auto' || v === 'none' ? v : Number(v);
  loadLadder();
};

// ---- the split: its edge on the trends dragged; on release the next jobs hold out that share ----

function dragSplit(div) {
  const g = () => wb.charts.trend;
  const xOf = (ev) => ev.clientX - g().graphDiv.getBoundingClientRect().left;
  const near = (ev) => {
    const area = g().getArea(), x = xOf(ev), x0 = g().toDomXCoord(nextSplitTime());
    return x0 > area.x && x0 < area.x + area.w && Math.abs(x - x0) <= 6;
  };
  // Capture: seen before dygraphs' own handlers, so a drag of the edge is no zoom.
  div.addEventListener('mousedown', (ev) => {
    if (!wb.loop || wb.loop.samples === 0 || !near(ev)) return;
    ev.stopPropagation();
    ev.preventDefault();
    wb.dragShare = nextShare();
    const move = (e) => {
      wb.dragShare = shareAt(g().toDataXCoord(xOf(e)));
      showSplitInfo();
      g().updateOptions({});
    };
    const up = (e) => {
      window.removeEventListener('mousemove', move, true);
      window.removeEventListener('mouseup', up, true);
      move(e);
      wb.validate = wb.dragShare;
      wb.dragShare = null;
      showSplitInfo();
      g().updateOptions({});
      drawPhasePlots();  // PV against OP coloured by the new split
    };
    window.addEventListener('mousemove', move, true);
    window.addEventListener('mouseup', up, true);
  }, true);
  div.addEventListener('mousemove', (ev) => {
    if (wb.charts.trend && wb.loop) div.classList.toggle('near-split', wb.dragShare !== null || near(ev));
  });
}

// ---- phase plots: the valve signature and PV against OP, paths drawn on a canvas -------------
// (dygraphs draws y against an ascending x; a cycle goes back and forth in OP)

const kEstimation = '#1f77b4', kHeldOut = '#ff7f0e';

function pathPoints(canvas) {
  return Math.max(400, Math.min(4000, 4 * Math.round(canvas.clientWidth || 500)));
}

// A path's estimation and held-out parts, each in data order; the held-out part starts at the
// estimation part's last point, so the path stays joined.
function splitPath(p, y, prefix = '') {
  const est = { label: prefix + 'estimation part', color: kEstimation, key: 'key-est', x: [], y: [] };
  const held = { label: prefix + 'held out', color: kHeldOut, key: 'key-held', x: [], y: [] };
  for (let k = 0; k < p.t.length; ++k) {
    const s = p.held_out[k] ? held : est;
    if (s === held && held.x.length === 0 && k > 0 && !p.held_out[k - 1]) {
      held.x.push(p.op[k - 1]);
      held.y.push(p[y][k - 1]);
    }
    s.x.push(p.op[k]);
    s.y.push(p[y][k]);
  }
  return [est, held].filter((s) => s.x.length > 0);
}

async function drawPhasePlots() {
  const l = wb.loop, a = wb.shown, b = wb.compare;
  const seq = (wb.phaseSeq = (wb.phaseSeq || 0) + 1);
  const range = wb.window ? '&from=' + wb.window[0] + '&to=' + wb.window[1] : '';
  const split = '&validate=' + nextShare();  // PV against OP: the next jobs' split
  const get = (path, canvas) => api('/api/loops/' + l.id + path + '?points=' + pathPoints($(canvas)) + range +
    (path === '/phase' ? split : ''))
    .catch((e) => ({ error: e.message }));
  if (l.samples === 0) return;
  const [phase, sa, sb] = await Promise.all([
    get('/phase', 'phase-chart'),
    a && a.valve_effect ? get('/models/' + a.step + '/signature', 'signature-chart') : null,
    b && b.valve_effect ? get('/models/' + b.step + '/signature', 'signature-chart') : null]);
  if (seq !== wb.phaseSeq || wb.loop.id !== l.id) return;  // a newer request is on its way
  drawXY('phase', phase.error ? { message: phase.error }
    : { xlabel: 'OP (%)', ylabel: 'PV', series: splitPath(phase, 'pv') });
  let sig;
  if (!a) sig = { message: 'No model yet.' };
  else if (!a.valve_effect) {
    sig = { message: 'Model A (' + a.model + ') has no valve effect: its valve position is OP itself. ' +
      'A model with stiction, deadband or another valve effect has a signature.' };
  } else if (sa.error) sig = { message: sa.error };
  else {
    const series = [];
    if (sb && !sb.error) {
      series.push({ label: 'B: step ' + b.step + ', ' + b.model, color: '#b0b0b0', key: 'key-grey', x: sb.op, y: sb.x });
    }
    sig = { xlabel: 'OP (%)', ylabel: sa.x_in_op_units ? 'valve position (%)' : 'valve position (scaled)',
      series: series.concat(splitPath(sa, 'x', 'A, ')), diagonal: sa.x_in_op_units };
  }
  drawXY('signature', sig);
  $('signature-model').textContent = a ? '(step ' + a.step + ', ' + a.model + ')' : '';
}

// Round tick values covering [lo, hi], about n of them.
function ticks(lo, hi, n) {
  const raw = (hi - lo) / Math.max(1, n), mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 5, 10].map((f) => f * mag).find((s) => s >= raw) || 10 * mag;
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step) out.push(Number(v.toPrecision(12)));
  return { values: out, digits: Math.max(0, -Math.floor(Math.log10(step) + 1e-9)) };
}

function wrapText(c, text, x, y, width, lineHeight) {
  let line = '';
  for (const word of text.split(' ')) {
    const next = line ? line + ' ' + word : word;
    if (c.measureText(next).width > width && line) {
      c.fillText(line, x, y);
      y += lineHeight;
      line = word;
    } else line = next;
  }
  if (line) c.fillText(line, x, y);
}

// An XY chart: each series a path in data order; a message instead when there is nothing to draw.
// spec: {xlabel, ylabel, series: [{label, color, key, x: [], y: []}], diagonal} or {message}.
function drawXY(name, spec) {
  const canvas = $(name + '-chart'), legend = $(name + '-legend');
  const dpr = window.devicePixelRatio || 1, w = canvas.clientWidth, h = canvas.clientHeight;
  canvas.width = Math.round(w * dpr);
  canvas.height = Math.round(h * dpr);
  const c = canvas.getContext('2d');
  c.setTransform(dpr, 0, 0, dpr, 0, 0);
  c.clearRect(0, 0, w, h);
  const info = (wb.xy[name] = { spec, points: 0, series: [], message: spec.message || null });
  legend.replaceChildren();
  let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
  for (const s of spec.series || []) {
    for (let k = 0; k < s.x.length; ++k) {
      if (s.x[k] === null || s.y[k] === null || !isFinite(s.x[k]) || !isFinite(s.y[k])) continue;
      x0 = Math.min(x0, s.x[k]); x1 = Math.max(x1, s.x[k]);
      y0 = Math.min(y0, s.y[k]); y1 = Math.max(y1, s.y[k]);
    }
  }
  if (!spec.message && !isFinite(x0)) info.message = spec.message = 'No samples to draw.';
  if (spec.message) {
    c.fillStyle = '#666';
    c.font = '12px "DejaVu Sans", Arial, sans-serif';
    wrapText(c, spec.message, 16, 28, w - 32, 17);
    return;
  }
  const pad = (lo, hi) => {
    const d = hi - lo > 1e-9 ? (hi - lo) * 0.04 : Math.max(1, Math.abs(hi) * 0.01);
    return [lo - d, hi + d];
  };
  [x0, x1] = pad(x0, x1);
  [y0, y1] = pad(y0, y1);
  const m = { l: 54, r: 10, t: 8, b: 38 }, pw = w - m.l - m.r, ph = h - m.t - m.b;
  const X = (x) => m.l + ((x - x0) / (x1 - x0)) * pw, Y = (y) => m.t + (1 - (y - y0) / (y1 - y0)) * ph;
  c.font = '11px "DejaVu Sans", Arial, sans-serif';
  c.lineWidth = 1;
  const tx = ticks(x0, x1, pw / 70), ty = ticks(y0, y1, ph / 35);
  for (const v of tx.values) {
    const px = Math.round(X(v)) + 0.5;
    c.strokeStyle = '#e5e8ec';
    c.beginPath(); c.moveTo(px, m.t); c.lineTo(px, m.t + ph); c.stroke();
    c.fillStyle = '#555';
    c.textAlign = 'center';
    c.fillText(v.toFixed(tx.digits), px, m.t + ph + 14);
  }
  for (const v of ty.values) {
    const py = Math.round(Y(v)) + 0.5;
    c.strokeStyle = '#e5e8ec';
    c.beginPath(); c.moveTo(m.l, py); c.lineTo(m.l + pw, py); c.stroke();
    c.fillStyle = '#555';
    c.textAlign = 'right';
    c.fillText(v.toFixed(ty.digits), m.l - 5, py + 4);
  }
  c.strokeStyle = '#999';
  c.strokeRect(m.l + 0.5, m.t + 0.5, pw, ph);
  c.fillStyle = '#333';
  c.textAlign = 'center';
  c.fillText(spec.xlabel, m.l + pw / 2, h - 6);
  c.save();
  c.translate(13, m.t + ph / 2);
  c.rotate(-Math.PI / 2);
  c.fillText(spec.ylabel, 0, 0);
  c.restore();
  c.save();
  c.beginPath();
  c.rect(m.l, m.t, pw, ph);
  c.clip();
  if (spec.diagonal) {  // where a valve without an effect would be: x = OP
    const lo = Math.min(x0, y0), hi = Math.max(x1, y1);
    c.strokeStyle = '#888';
    c.setLineDash([5, 4]);
    c.beginPath(); c.moveTo(X(lo), Y(lo)); c.lineTo(X(hi), Y(hi)); c.stroke();
    c.setLineDash([]);
  }
  for (const s of spec.series) {
    c.strokeStyle = s.color;
    c.lineWidth = 1.2;
    c.lineJoin = 'round';
    c.beginPath();
    let pen = false, n = 0;
    for (let k = 0; k < s.x.length; ++k) {
      if (s.x[k] === null || s.y[k] === null) { pen = false; continue; }
      if (pen) c.lineTo(X(s.x[k]), Y(s.y[k])); else c.moveTo(X(s.x[k]), Y(s.y[k]));
      pen = true;
      ++n;
    }
    c.stroke();
    info.points += n;
    info.series.push({ label: s.label, points: n });
    legend.append(el('span', { class: 'item' }, el('span', { class: 'key ' + s.key }), s.label));
  }
  c.restore();
  // The diagonal's key only where it crosses the plot (a zoomed window may lie beside it).
  if (spec.diagonal && Math.max(x0, y0) <= Math.min(x1, y1)) legend.append(el('span', { class: 'item' }, el('span', { class: 'key key-diag' }), 'valve = OP'));
}

// Canvases do not follow the page's width by themselves: drawn again at the new size.
window.addEventListener('resize', () => {
  clearTimeout(wb.resizeTimer);
  wb.resizeTimer = setTimeout(() => {
    for (const [name, x] of Object.entries(wb.xy)) drawXY(name, x.spec);
  }, 150);
});

// The effects of the ladder's last model (the one a job starts from), each one Remove away.
function showRemovable(step) {
  const effects = step && step.model !== 'linear' ? step.model.split('+') : [];
  const sel = $('remove-effect');
  sel.replaceChildren(...effects.map((e) => el('option', { value: e, textContent: e })));
  $('remove-box').hidden = effects.length === 0;
}

// ---- the ladder -------------------------------------------------------------------------------

async function loadLadder() {
  const id = wb.loop.id;
  const lad = await api('/api/loops/' + id + '/ladder');
  if (wb.loop.id !== id) return;
  wb.ladder = lad.steps;
  if (wb.ladder.length > 0 && (!wb.shown || wb.shown.step >= wb.ladder.length || wb.followLast)) {
    wb.shown = wb.ladder[wb.ladder.length - 1];
  } else if (wb.shown) {
    wb.shown = wb.ladder[wb.shown.step];
  }
  resolveCompare();
  fillPickers();
  const body = $('ladder').tBodies[0];
  body.replaceChildren();
  for (const s of wb.ladder) {
    const change = s.validation_fitness_change;
    const tr = el('tr', { 'data-step': s.step, 'data-validation': s.validation_fitness_percent ?? '',
      'data-estimation': s.fitness_percent ?? '', 'data-model': s.model },
      el('td', { textContent: s.step }),
      el('td', { class: 'tag', textContent: wb.shown && s.step === wb.shown.step ? 'A'
        : wb.compare && s.step === wb.compare.step ? 'B' : '' }),
      el('td', { class: 'model', textContent: s.model, title: s.action }),
      el('td', { class: 'num', textContent: fmt(s.fitness_percent) + ' %' }),
      el('td', { class: 'num', textContent: fmt(s.validation_fitness_percent) + ' %' }),
      el('td', { class: 'num ' + (change > 0 ? 'up' : change < 0 ? 'down' : ''), textContent: signed(change) }),
      el('td', {}, el('a', { href: '/api/loops/' + id + '/models/' + s.step, textContent: 'JSON' })));
    if (wb.shown && s.step === wb.shown.step) tr.classList.add('current');
    if (wb.compare && s.step === wb.compare.step) tr.classList.add('compared');
    tr.onclick = (ev) => {
      if (ev.target.tagName === 'A') return;
      showStep(s.step);
    };
    body.append(tr);
  }
  drawLadderChart();
  showRemovable(wb.ladder[wb.ladder.length - 1]);
  await drawModel();
}

function drawLadderChart() {
  const rows = wb.ladder.map((s) => [s.step, s.fitness_percent, s.validation_fitness_percent]);
  const opts = {
    labels: ['step', 'estimation %', 'validation %'], colors: ['#1f77b4', '#ff7f0e'],
    drawPoints: true, pointSize: 4, strokeWidth: 1.5, legend: 'always', axisLabelFontSize: 11,
    labelsDiv: wb.ladderLegend || (wb.ladderLegend = legendFor($('ladder-chart'))),
    xlabel: 'model step', ylabel: 'fitness %', includeZero: false,
    axes: {
      x: {
        valueFormatter: (x) => 'step ' + x,
        ticker: (lo, hi) => {  // one tick per step, whole numbers only
          const t = [];
          for (let k = Math.ceil(lo); k <= Math.floor(hi); ++k) t.push({ v: k, label: String(k) });
          return t;
        },
      },
      y: { pixelsPerLabel: 20 },
    },
  };
  // The y range from the points (dygraphs pads a single point badly), at least 10 points high.
  const ys = rows.flatMap((r) => r.slice(1)).filter((y) => y !== null && isFinite(y));
  if (ys.length > 0) {
    const lo = Math.min(...ys), hi = Math.max(...ys), pad = Math.max(5, (hi - lo) * 0.1);
    opts.valueRange = [Math.floor(lo - pad), Math.min(100, Math.ceil(hi + pad))];
  }
  if (rows.length === 0) rows.push([0, null, null]);
  if (rows.length === 1) opts.dateWindow = [-0.5, 0.5];
  else opts.dateWindow = [-0.2, rows.length - 0.8];
  if (!wb.charts.ladder) wb.charts.ladder = new Dygraph($('ladder-chart'), rows, opts);
  else wb.charts.ladder.updateOptions(Object.assign({ file: rows }, opts));
}

// ---- findings ---------------------------------------------------------------------------------

async function loadDiagnosis() {
  const id = wb.loop.id;
  let d = null;
  try {
    d = await api('/api/loops/' + id + '/diagnosis');
  } catch (e) {
    if (e.status !== 404) throw e;
  }
  if (wb.loop.id !== id) return;
  showFindings(d);
}

function showFindings(d) {
  const body = $('findings').tBodies[0];
  body.replaceChildren();
  $('findings-model').textContent = d ? '(missing from ' + d.model + ')' : '';
  $('conclusion').textContent = d ? d.conclusion : 'No diagnosis yet.';
  if (!d) return;
  for (const f of d.findings) {
    const add = el('button', { type: 'button', textContent: 'Add', className: 'add' });
    add.disabled = !!wb.job;
    add.onclick = () => runJob({ action: 'add', effect: f.effect }, 'adding ' + f.effect, true);
    const tr = el('tr', { 'data-effect': f.effect, class: f.supported ? 'supported' : '' },
      el('td', { textContent: f.effect }),
      el('td', { class: 'num', textContent: fmt(f.score, 2) }),
      el('td', { class: 'num', textContent: signed(f.validation_gain_percent) }),
      el('td', { textContent: f.explanation }),
      el('td', {}, add));
    body.append(tr);
  }
}

// ---- jobs -------------------------------------------------------------------------------------

function setBusy(busy) {
  document.body.dataset.job = busy ? 'running' : 'idle';
  $('diagnose-btn').disabled = busy;
  $('remove-btn').disabled = busy;
  for (const b of document.querySelectorAll('button.add')) b.disabled = busy;
}

// Starts a job on the loop shown and follows it; `rediagnose`: diagnose the new model after it.
async function runJob(body, text, rediagnose = false) {
  const id = wb.loop.id;
  // The split dragged, and "fit the last N minutes": every job the page starts uses them.
  if (wb.validate !== null) body.validate = wb.validate;
  const minutes = Number($('last-min').value);
  if ($('last-on').checked && minutes > 0) {
    body.last_s = minutes * 60;
    text += ' (the last ' + minutes + ' min)';
  }
  wb.jobs.push(body);
  showError('');
  setBusy(true);
  let job;
  try {
    job = await api('/api/loops/' + id + '/jobs', {
      method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body),
    });
  } catch (e) {
    setBusy(false);
    showError('Could not start the job: ' + e.message);
    return;
  }
  wb.job = job.job;
  $('job').hidden = false;
  $('job-cancel').disabled = false;
  let st = job;
  while (st.state === 'queued' || st.state === 'running') {
    $('job-text').textContent = text + ': ' + st.state + (st.phase ? ', ' + st.phase : '') +
      ' (' + fmt(st.elapsed_s, 0) + ' s)';
    $('job-progress').value = st.progress || 0;
    await new Promise((r) => setTimeout(r, 400));
    try {
      st = await api('/api/jobs/' + wb.job);
    } catch (e) {
      st = { state: 'failed', error: e.message };
    }
  }
  wb.job = null;
  $('job').hidden = true;
  if (st.state === 'failed') showError(text + ' failed: ' + st.error);
  if (st.state === 'cancelled') showError(text + ': cancelled');
  // Idle only once the new ladder and diagnosis are drawn: a click before would land on a
  // picker or a finding that is about to be replaced.
  if (st.state === 'done' && wb.loop.id === id) {
    wb.followLast = true;
    wb.compareChoice = 'auto';  // the new model beside the one before it
    try {
      await loadLadder();
      await loadDiagnosis();
    } catch (e) {
      showError(e.message);
    }
  }
  wb.history.push(text + ': ' + st.state);
  setBusy(false);
  if (st.state === 'done' && wb.loop.id === id && rediagnose) {
    runJob({ action: 'diagnose' }, 'diagnosing ' + wb.shown.model);
  }
}

$('job-cancel').onclick = () => {
  if (!wb.job) return;
  $('job-cancel').disabled = true;
  api('/api/jobs/' + wb.job, { method: 'DELETE' }).catch((e) => showError(e.message));
};
$('remove-btn').onclick = () => {
  const e = $('remove-effect').value;
  if (e) runJob({ action: 'remove', effect: e }, 'removing ' + e, true);
};
$('diagnose-btn').onclick = () => runJob({ action: 'diagnose' }, 'diagnosing ' + (wb.shown ? wb.shown.model : 'linear'));

// ---- live: the recording grows; the trends and the bus status follow it ------------------------

async function pollLive() {
  if (!wb.loops.some((l) => l.live)) return;
  try {
    const [loops, st] = await Promise.all([api('/api/loops'), api('/api/status')]);
    wb.status = st;
    showLive(st);
    for (const l of loops.loops) {
      const li = document.querySelector('#loop-list li[data-id="' + l.id + '"] .muted');
      if (li) li.textContent = loopSize(l);
      const i = wb.loops.findIndex((x) => x.id === l.id);
      if (i >= 0) wb.loops[i] = l;
    }
    const now = wb.loop && wb.loops.find((l) => l.id === wb.loop.id);
    if (now && now.samples !== wb.loop.samples) {
      wb.loop = now;
      $('loop-info').textContent = loopInfo(now);
      if (wb.dragShare === null) {  // not under a drag of the split
        await drawTrends();
        if (!wb.shown && wb.charts.fit) drawMeasuredPv();  // no model yet: it grows too
      }
    }
  } catch (e) {
    $('live-text').textContent = ' (the server did not answer: ' + e.message + ')';
  }
  setTimeout(pollLive, 1000);
}

function showLive(st) {
  $('live').hidden = false;
  $('live').classList.toggle('stopped', !st.recording);
  $('live-db').textContent = st.db + ' (run ' + st.run + ')';
  const ms = (s) => fmt(1000 * s, 1) + ' ms';
  const buses = st.buses.map((b) => 'bus ' + b.name + (b.connected ? ' up' : ' DOWN') + ': ' + b.requests +
    ' requests, ' + b.errors + ' errors, ' + b.reconnects + ' reconnects' +
    (b.last_error ? ' (' + b.last_error + ')' : ''));
  $('live-text').textContent = (st.recording ? '' : ' stopped' + (st.error ? ': ' + st.error : '') + '; ') +
    ' ' + st.stored + ' samples stored, ' + st.bad_rows + ' with errors, ' + st.missed + ' missed; lateness p50 ' +
    ms(st.lateness_p50_s) + ', p99 ' + ms(st.lateness_p99_s) + '; ' + buses.join('; ');
}

// The token came in the address (?token=): the cookie carries it now, the address bar need not.
if (location.search.includes('token=')) history.replaceState(null, '', location.pathname);
document.body.dataset.job = 'idle';
loadLoops().then(pollLive).catch((e) => showError('Could not read the loops: ' + e.message));
