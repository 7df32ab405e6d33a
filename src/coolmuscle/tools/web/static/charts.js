/* coolmuscle dashboard: the charts (uPlot, bundled in vendor/) and the XY path.
 *
 * Per motor, position and target in one chart, speed and torque (its own % scale) in
 * a second one, over the chosen window of virtual time; the XY path of two motors on
 * a canvas (an interpolating pair, cml-users-guide.txt 4.4).
 */
"use strict";

window.Coolmuscle = window.Coolmuscle || {};

window.Coolmuscle.charts = function (state, $) {
  // -- charts --------------------------------------------------------------------
  function resetSeries() {
    for (const id of state.motors) {
      const old = state.series.get(id);
      if (old) { old.top.destroy(); old.bottom.destroy(); }
      const card = state.cards.get(id);
      if (!card) continue;
      // with a twin (coolmuscle web --twin) its position, speed and torque are drawn
      // over the real ones, dashed: data [t, pos, tgt, spd, trq, tpos, tspd, ttrq]
      const data = [[], [], [], [], [], [], [], []];
      const width = Math.max(200, card.chartBox.clientWidth || 300);
      const topSeries = [
        { label: "position", stroke: "#1f6feb", width: 2 },
        { label: "target", stroke: "#d29922", width: 1, dash: [6, 4],
          paths: uPlot.paths.stepped({ align: 1 }) },
      ];
      const bottomSeries = [
        { label: "speed", stroke: "#2da44e", width: 1.5 },
        { label: "torque %", stroke: "#cf222e", width: 1.5, scale: "%" },
      ];
      if (state.twin) {
        topSeries.push({ label: "twin position", stroke: "#8250df", width: 2, dash: [4, 3] });
        bottomSeries.push({ label: "twin speed", stroke: "#1b7c83", width: 1.5, dash: [4, 3] },
          { label: "twin torque %", stroke: "#bf3989", width: 1.5, dash: [4, 3], scale: "%" });
      }
      const top = new uPlot(chartOpts(width, 130, topSeries, "pulses"),
        topCols(data), card.chartBox);
      const bottom = new uPlot(chartOpts(width, 110, bottomSeries, "speed"),
        bottomCols(data), card.chartBox);
      state.series.set(id, { data, top, bottom });
    }
  }

  function chartOpts(width, height, series, label) {
    const axes = [{ stroke: "#57606a", grid: { stroke: "#eaeef2" } },
      { stroke: "#57606a", grid: { stroke: "#eaeef2" }, size: 60, label, labelSize: 14 }];
    const scales = { x: { time: false, range: () => {
      const now = state.lastTime / 1e9, span = Number($("window").value);
      return [Math.max(0, now - span), Math.max(now, span)];
    } } };
    if (series.some((s) => s.scale === "%")) {
      axes.push({ side: 1, scale: "%", stroke: "#cf222e", grid: { show: false }, size: 44 });
      scales["%"] = { auto: true };
    }
    return { width, height, series: [{ label: "t (s)" }].concat(series), axes, scales,
      legend: { show: true, live: false }, cursor: { show: false } };
  }

  function topCols(d) { return state.twin ? [d[0], d[1], d[2], d[5]] : [d[0], d[1], d[2]]; }
  function bottomCols(d) { return state.twin ? [d[0], d[3], d[4], d[6], d[7]] : [d[0], d[3], d[4]]; }

  function pushSample(id, t, pos, tgt, spd, trq, twin) {
    const s = state.series.get(id);
    if (!s) return;
    const d = s.data;
    if (d[0].length && t < d[0][d[0].length - 1]) { d.forEach((a) => { a.length = 0; }); }
    const tw = twin || [null, null, null];
    d[0].push(t); d[1].push(pos); d[2].push(tgt); d[3].push(spd); d[4].push(trq);
    d[5].push(tw[0]); d[6].push(tw[1]); d[7].push(tw[2]);
    const window = Number($("window").value);
    let cut = 0;
    while (cut < d[0].length && d[0][cut] < t - window) cut++;
    if (cut > 0) d.forEach((a) => a.splice(0, cut));
  }

  function redraw() {
    if (state.dirty) {
      state.dirty = false;
      for (const [, s] of state.series) {
        const d = s.data;
        if (!d[0].length) continue;
        // run the last value on to "now", so an idle motor's line reaches the present
        const now = state.lastTime / 1e9;
        const x = d[0].slice(), y = (k) => d[k].slice();
        if (now > x[x.length - 1]) { x.push(now); }
        const pad = (arr) => { if (arr.length < x.length) arr.push(arr[arr.length - 1]); return arr; };
        const cols = d.map((_, k) => (k ? pad(y(k)) : x));
        s.top.setData(topCols(cols));
        s.bottom.setData(bottomCols(cols));
      }
      drawXY();
    }
    requestAnimationFrame(redraw);
  }

  function drawXY() {
    const canvas = $("xy");
    const ctx = canvas.getContext("2d");
    const xs = state.series.get(Number($("xy-x").value));
    const ys = state.series.get(Number($("xy-y").value));
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    ctx.strokeStyle = "#d0d7de";
    ctx.strokeRect(0.5, 0.5, canvas.width - 1, canvas.height - 1);
    if (!xs || !ys || xs === ys) return;
    const n = Math.min(xs.data[1].length, ys.data[1].length);
    if (!n) return;
    const X = xs.data[1].slice(-n), Y = ys.data[1].slice(-n);
    let x0 = Math.min(...X), x1 = Math.max(...X), y0 = Math.min(...Y), y1 = Math.max(...Y);
    const span = Math.max(x1 - x0, y1 - y0, 1);
    const m = 16, w = canvas.width - 2 * m, h = canvas.height - 2 * m;
    const px = (v) => m + ((v - x0) / span) * w, py = (v) => canvas.height - m - ((v - y0) / span) * h;
    ctx.strokeStyle = "#1f6feb";
    ctx.lineWidth = 2;
    ctx.beginPath();
    for (let i = 0; i < n; i++) { if (i) ctx.lineTo(px(X[i]), py(Y[i])); else ctx.moveTo(px(X[i]), py(Y[i])); }
    ctx.stroke();
    ctx.fillStyle = "#cf222e";
    ctx.beginPath(); ctx.arc(px(X[n - 1]), py(Y[n - 1]), 4, 0, 2 * Math.PI); ctx.fill();
  }

  function resizeCharts() {
    for (const [id, s] of state.series) {
      const card = state.cards.get(id);
      const width = Math.max(200, card.chartBox.clientWidth);
      s.top.setSize({ width, height: 130 });
      s.bottom.setSize({ width, height: 110 });
    }
  }


  return { resetSeries, pushSample, redraw, resizeCharts };
};
