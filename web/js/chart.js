// chart.js: the Server-Timing of a view as a small horizontal bar chart in plain SVG
// (no chart library): one bar per stage the server ran (parse, queue, trace, each
// effect, encode...), in header order, all charts of a comparison on one scale so
// their bars can be compared by eye. A `total` entry, when the server sends one, is the
// caption rather than a bar (it would dwarf the stages it sums). A `pagein` entry (the
// wait for pages of a prepared dataset) is a bar but not added to the total: it is part
// of the stages' time, mostly trace's.

const SVG = 'http://www.w3.org/2000/svg';
const PALETTE = ['#4e79a7', '#f28e2b', '#59a14f', '#e15759', '#76b7b2', '#edc948',
  '#b07aa1', '#ff9da7', '#9c755f', '#bab0ac'];

function el(name, attrs, text) {
  const e = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, String(v));
  if (text != null) e.textContent = text;
  return e;
}

function colour(name) {
  let h = 0;
  for (const ch of name) h = (h * 31 + ch.charCodeAt(0)) >>> 0;
  return PALETTE[h % PALETTE.length];
}

export function stagesOf(info) {
  return info.timing.filter((t) => t.dur != null && t.name !== 'total');
}

export function totalOf(info) {
  const t = info.timing.find((e) => e.name === 'total' && e.dur != null);
  return t ? t.dur : stagesOf(info).filter((e) => e.name !== 'pagein').reduce((s, e) => s + e.dur, 0);
}

export function fmtMs(ms) {
  return ms >= 100 ? `${ms.toFixed(0)} ms` : ms >= 10 ? `${ms.toFixed(1)} ms` : `${ms.toFixed(2)} ms`;
}

// Draws into `host` (emptied first). scaleMs: the duration of the full bar width.
export function drawTimingChart(host, info, scaleMs, title) {
  const stages = stagesOf(info);
  const rowH = 16, labelW = 92, valueW = 62, width = 360;
  const barW = width - labelW - valueW;
  const height = 22 + Math.max(stages.length, 1) * rowH + 4;
  const svg = el('svg', {
    class: 'timing-chart', width, height, viewBox: `0 0 ${width} ${height}`, role: 'img',
    'aria-label': `${title}: ` + (stages.map((s) => `${s.name} ${fmtMs(s.dur)}`).join(', ') || 'no timing'),
  });
  const total = totalOf(info);
  let caption = `${title}: ${fmtMs(total)}`;
  if (info.stepsPerRay != null && Number.isFinite(info.stepsPerRay)) caption += `, ${info.stepsPerRay.toFixed(1)} steps/ray`;
  svg.append(el('text', { x: 0, y: 13, class: 'chart-title' }, caption));
  const scale = scaleMs > 0 ? barW / scaleMs : 0;
  stages.forEach((s, i) => {
    const y = 22 + i * rowH;
    const g = el('g', { class: 'bar', 'data-stage': s.name });
    g.append(el('title', {}, `${s.name}${s.desc ? ' (' + s.desc + ')' : ''}: ${fmtMs(s.dur)}`));
    g.append(el('text', { x: labelW - 4, y: y + 11, 'text-anchor': 'end' }, s.desc || s.name));
    g.append(el('rect', {
      x: labelW, y: y + 2, height: rowH - 4,
      width: Math.max(1, s.dur * scale), fill: colour(s.name),
    }));
    g.append(el('text', { x: labelW + Math.max(1, s.dur * scale) + 4, y: y + 11 }, fmtMs(s.dur)));
    svg.append(g);
  });
  if (!stages.length) svg.append(el('text', { x: 0, y: 34 }, 'no Server-Timing in the response'));
  host.replaceChildren(svg);
  return svg;
}
