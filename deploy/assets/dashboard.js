// The run page's script (indrive dashboard), embedded into the program at build time.
// Draws every chart, records what it holds in data-* attributes of <body> (read by the
// browser test) and wires hover, drag-to-zoom (double-click resets) and smoothing.
(function () {
  const errors = [];
  const report = () => { document.body.dataset.errors = JSON.stringify(errors); };
  window.addEventListener('error', e => { errors.push(String(e.message)); report(); });
  report();
  const palette = ['#1f77b4', '#ff7f0e', '#2ca02c', '#d62728', '#9467bd', '#8c564b',
                   '#e377c2', '#7f7f7f', '#bcbd22', '#17becf'];
  const colour = (i, alpha) => {
    const c = palette[i % palette.length];
    if (alpha === undefined) return c;
    const n = parseInt(c.slice(1), 16);
    return `rgba(${n >> 16},${(n >> 8) & 255},${n & 255},${alpha})`;
  };
  const points = (xs, ys) => {
    const out = [];
    for (let i = 0; i < ys.length; ++i) if (ys[i] !== null && xs[i] !== null) out.push({x: xs[i], y: ys[i]});
    return out;
  };
  const smooth = (raw, weight) => {
    if (weight <= 0 || raw.length < 50) return raw;
    let ema = raw[0].y;
    return raw.map(p => { ema = weight * ema + (1 - weight) * p.y; return {x: p.x, y: ema}; });
  };
  // Axis ticks: plain numbers with a few significant digits, exponents only where needed.
  const tick = v => {
    const a = Math.abs(v);
    if (a !== 0 && (a < 1e-3 || a >= 1e7)) return Number(v).toExponential(1);
    return Number(v).toLocaleString('en', {maximumSignificantDigits: 4});
  };
  const charts = [];
  const counts = {};
  for (const spec of DATA.charts) {
    const canvas = document.getElementById(spec.id);
    const datasets = [];
    for (const s of spec.series) {
      const xs = DATA.xs[s.xi];
      if (s.low) {
        datasets.push({label: '\u200b' + s.label + ' low', data: points(xs, s.low), borderWidth: 0,
                       pointRadius: 0, fill: false, backgroundColor: colour(s.colour, 0.15)});
        datasets.push({label: '\u200b' + s.label + ' high', data: points(xs, s.high), borderWidth: 0,
                       pointRadius: 0, fill: '-1', backgroundColor: colour(s.colour, 0.15)});
      }
      const raw = points(xs, s.y);
      datasets.push({label: s.label, raw: raw, data: raw, borderColor: colour(s.colour),
                     backgroundColor: colour(s.colour), borderWidth: 1.5,
                     pointRadius: raw.length < 30 ? 2.5 : 0, fill: false});
    }
    const chart = new Chart(canvas, {
      type: 'line',
      data: {datasets: datasets},
      options: {
        animation: false, parsing: false, normalized: true, spanGaps: true,
        maintainAspectRatio: false,
        interaction: {mode: 'nearest', axis: 'x', intersect: false},
        scales: {x: {type: 'linear', title: {display: true, text: DATA.x_key},
                     ticks: {callback: tick}},
                 y: {title: {display: spec.y_label !== '', text: spec.y_label},
                     ticks: {callback: tick}}},
        plugins: {
          title: {display: true, text: spec.title},
          legend: {labels: {boxWidth: 12, filter: item => !item.text.startsWith('\u200b')}},
          tooltip: {filter: item => !item.dataset.label.startsWith('\u200b')},
          decimation: {enabled: true, algorithm: 'lttb', samples: 800, threshold: 1000}
        }
      }
    });
    charts.push(chart);
    counts[spec.title] = {};
    for (const d of chart.data.datasets) {
      if (d.label.startsWith('\u200b')) continue;
      counts[spec.title][d.label] = (d._data || d.data).length;
    }
    // Drag across a chart to zoom into that range of the x axis; double-click to reset.
    const box = document.createElement('div');
    box.className = 'zoombox';
    canvas.parentNode.appendChild(box);
    let start = null;
    canvas.addEventListener('mousedown', e => { start = e.offsetX; });
    canvas.addEventListener('mousemove', e => {
      if (start === null) return;
      const area = chart.chartArea;
      box.style.display = 'block';
      box.style.left = (canvas.offsetLeft + Math.min(start, e.offsetX)) + 'px';
      box.style.width = Math.abs(e.offsetX - start) + 'px';
      box.style.top = (canvas.offsetTop + area.top) + 'px';
      box.style.height = (area.bottom - area.top) + 'px';
    });
    window.addEventListener('mouseup', e => {
      if (start === null) return;
      const end = e.target === canvas ? e.offsetX : start;
      box.style.display = 'none';
      if (Math.abs(end - start) > 5) {
        const scale = chart.scales.x;
        chart.options.scales.x.min = scale.getValueForPixel(Math.min(start, end));
        chart.options.scales.x.max = scale.getValueForPixel(Math.max(start, end));
        chart.update('none');
      }
      start = null;
    });
    canvas.addEventListener('dblclick', () => {
      delete chart.options.scales.x.min;
      delete chart.options.scales.x.max;
      chart.update('none');
    });
  }
  const smoothing = document.getElementById('smoothing');
  if (smoothing) smoothing.addEventListener('change', () => {
    const weight = parseFloat(smoothing.value);
    for (const chart of charts) {
      for (const d of chart.data.datasets) if (d.raw) d.data = smooth(d.raw, weight);
      chart.update('none');
    }
  });
  document.body.dataset.points = JSON.stringify(counts);
  document.body.dataset.charts = String(charts.length);
  document.body.dataset.ready = '1';
})();
