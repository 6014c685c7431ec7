# ruff: noqa: E501
"""The report page's style sheet and script (inline in the page: no file, no network)."""

CSS = """
:root { --fg:#1b1b1b; --muted:#5b6470; --line:#d9dde3; --flag:#fff3c4; --flagfg:#8a1c00; --fail:#fde2e1; }
* { box-sizing: border-box; }
body { font: 15px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif;
       color: var(--fg); margin: 0; background: #f6f7f9; }
header { background: #1f2a37; color: #fff; padding: 18px 28px 14px; }
header h1 { margin: 0 0 4px; font-size: 24px; }
header p { margin: 2px 0; color: #d5dbe3; }
nav { position: sticky; top: 0; z-index: 10; background: #fff; border-bottom: 1px solid var(--line);
      padding: 6px 28px; font-size: 14px; }
nav a { margin-right: 14px; color: #1f5fbf; text-decoration: none; }
main { max-width: 1240px; margin: 0 auto; padding: 8px 20px 40px; }
section { background: #fff; border: 1px solid var(--line); border-radius: 6px; margin: 16px 0;
          padding: 12px 18px; }
h2 { font-size: 19px; margin: 4px 0 8px; }
.note { color: var(--muted); font-size: 13.5px; }
.fig { width: 100%; }
table { border-collapse: collapse; font-size: 13px; }
th, td { border-bottom: 1px solid var(--line); padding: 4px 7px; text-align: right; vertical-align: top; }
th { background: #eef1f5; position: sticky; top: 0; }
td.l, th.l { text-align: left; }
table.k td.m { font-family: ui-monospace, "DejaVu Sans Mono", monospace; white-space: pre; font-size: 12px; }
tr.flagged { background: var(--flag); }
tr.flagged td.flags { color: var(--flagfg); font-weight: 600; }
tr.failed { background: var(--fail); }
.tablewrap { overflow-x: auto; max-height: 720px; overflow-y: auto; }
.kv td { text-align: left; border: none; padding: 2px 12px 2px 0; }
.pill { display: inline-block; padding: 1px 8px; border-radius: 10px; background: #eef1f5; margin-right: 6px; }
.pill.bad { background: var(--fail); }
.pill.warn { background: var(--flag); }
label.ctl { margin-right: 16px; font-size: 14px; }
select { font-size: 14px; padding: 2px 4px; }
ul.fail li { margin: 2px 0; }
code { font-size: 13px; }
"""

JS = r"""
(function () {
  "use strict";
  const config = {displaylogo: false, responsive: true};
  const parse = (id) => JSON.parse(document.getElementById(id).textContent);
  const jobs = [];
  document.querySelectorAll("script[data-figure]").forEach((s) => {
    const fig = JSON.parse(s.textContent);
    const div = document.getElementById(s.dataset.figure);
    jobs.push(Plotly.newPlot(div, fig.data, fig.layout, config));
  });

  // Per-position load cases: bars of mean +- std with the repeats (reference Figs. 9-10).
  const loadsEl = document.getElementById("loads-data");
  if (loadsEl) {
    const D = JSON.parse(loadsEl.textContent);
    const pos = document.getElementById("pos-select");
    const load = document.getElementById("load-select");
    D.positions.forEach((p, i) => {
      const o = document.createElement("option");
      o.value = i; o.textContent = p + (D.status[i] === "ok" ? "" : "  [failed]");
      pos.appendChild(o);
    });
    D.labels.forEach((l, j) => {
      const o = document.createElement("option");
      o.value = j; o.textContent = (j + 1) + ": " + l;
      load.appendChild(o);
    });
    const detail = document.getElementById("fig-load-detail");
    const num = (v) => (v === null || v === undefined ? NaN : v);
    function draw() {
      const i = +pos.value, j = +load.value;
      const L = D.labels.length, R = D.norms[i][0].length;
      const xs = [], ys = [], rx = [], ry = [], rt = [];
      for (let k = 0; k < L; k++) {
        xs.push(k); ys.push(num(D.mean[i][k]));
        for (let r = 0; r < R; r++) {
          const v = D.norms[i][k][r];
          if (v !== null) { rx.push(k - 0.28 + 0.56 * (R > 1 ? r / (R - 1) : 0.5)); ry.push(v); rt.push("repeat " + (r + 1)); }
        }
      }
      const reps = D.norms[i][j].map((v, r) => [r + 1, v]).filter((a) => a[1] !== null);
      const m = num(D.mean[i][j]), s = num(D.std[i][j]);
      const ticks = D.labels.map((l, k) => (k + 1) + ": " + l);
      const data = [
        {type: "bar", x: xs, y: ys, name: "mean", marker: {color: "#9ecae1"},
         error_y: {type: "data", array: D.std[i].map((v) => (v === null ? 0 : v)), visible: true, color: "#2b5d8a"},
         customdata: D.count[i], hovertemplate: "%{y:.4g} mm (n = %{customdata})<extra>mean ± std</extra>"},
        {type: "scatter", mode: "markers", x: rx, y: ry, text: rt, name: "repeats",
         marker: {size: 5, color: "#08306b"}, hovertemplate: "%{text}: %{y:.4g} mm<extra></extra>"},
        {type: "scatter", mode: "lines+markers", x: reps.map((a) => a[0]), y: reps.map((a) => a[1]),
         xaxis: "x2", yaxis: "y2", name: "repeats of " + D.labels[j], marker: {size: 8, color: "#08306b"},
         line: {color: "#9ab", width: 1}, hovertemplate: "repeat %{x}: %{y:.5g} mm<extra></extra>"},
      ];
      const shapes = [];
      if (isFinite(m)) {
        shapes.push({type: "line", xref: "x2", yref: "y2", x0: 0.5, x1: R + 0.5, y0: m, y1: m, line: {color: "#d62728", width: 2}});
        if (isFinite(s)) shapes.push({type: "rect", xref: "x2", yref: "y2", x0: 0.5, x1: R + 0.5, y0: m - s, y1: m + s,
                                      fillcolor: "rgba(214,39,40,0.12)", line: {width: 0}});
      }
      const note = D.status[i] === "ok" ? "" : "  —  failed: " + D.messages[i];
      const F = D.forces[j].map((v) => (+v).toFixed(3)).join(", ");
      const layout = {
        template: {layout: {paper_bgcolor: "white", plot_bgcolor: "white"}}, height: 420,
        margin: {l: 60, r: 20, t: 60, b: 110}, showlegend: false,
        title: {text: D.positions[i] + note, x: 0.01, font: {size: 15}},
        xaxis: {domain: [0, 0.58], tickmode: "array", tickvals: xs, ticktext: ticks, tickangle: -35,
                gridcolor: "#eee", title: {text: "load case"}},
        yaxis: {title: {text: "displacement norm (mm)"}, rangemode: "tozero", gridcolor: "#eee"},
        xaxis2: {domain: [0.68, 1], anchor: "y2", title: {text: "repeat"}, dtick: 1, range: [0.5, R + 0.5], gridcolor: "#eee"},
        yaxis2: {anchor: "x2", title: {text: "norm (mm)"}, gridcolor: "#eee"},
        shapes: shapes,
        annotations: [{xref: "paper", yref: "paper", x: 1, y: 1.08, showarrow: false, xanchor: "right",
                       text: "load " + (j + 1) + " (F = " + F + " N): mean " + (isFinite(m) ? m.toPrecision(4) : "n/a") +
                             " mm ± " + (isFinite(s) ? s.toPrecision(2) : "n/a")}],
      };
      return Plotly.react(detail, data, layout, config);
    }
    // Linearity and residuals of the chosen position (when the data hold the displacement vectors).
    const linEl = document.getElementById("fig-linearity");
    const resEl = document.getElementById("fig-residual-detail");
    const COLOURS = ["#1f77b4", "#2ca02c", "#9467bd"], COMP = ["dx", "dy", "dz"];
    function drawLinearity() {
      if (!linEl || !D.vectors) return Promise.resolve();
      const i = +pos.value, G = D.directions, data = [], layout = {
        template: {layout: {paper_bgcolor: "white", plot_bgcolor: "white"}}, height: 380,
        margin: {l: 60, r: 20, t: 50, b: 90}, showlegend: true, legend: {orientation: "h", x: 0, y: -0.22},
        title: {text: D.positions[i] + ": displacement against the force, per load direction (dots: repeats; lines: d = C·F from the identified K)", x: 0.01, font: {size: 13}},
        annotations: []};
      G.forEach((g, k) => {
        const ax = k === 0 ? "" : String(k + 1), w = 1 / G.length;
        layout["xaxis" + ax] = {domain: [k * w + 0.04, (k + 1) * w - 0.03], anchor: "y" + ax, title: {text: "|F| (N), along " + g.label}, rangemode: "tozero", gridcolor: "#eee"};
        layout["yaxis" + ax] = {anchor: "x" + ax, title: {text: k === 0 ? "displacement (mm)" : ""}, gridcolor: "#eee", zeroline: true};
        for (let c = 0; c < 3; c++) {
          const mx = [], my = [], lx = [], ly = [];
          g.loads.forEach((j, q) => {
            const f = g.magnitude[q];
            let sum = 0, cnt = 0;
            D.vectors[i][j].forEach((v, r) => {
              if (v[c] === null) return;
              mx.push(f); my.push(v[c]);
              const e = D.residuals[i][j][r][c];
              if (e !== null) { sum += v[c] - e; cnt++; }
            });
            if (cnt) { lx.push(f); ly.push(sum / cnt); }
          });
          data.push({type: "scatter", mode: "markers", x: mx, y: my, xaxis: "x" + ax, yaxis: "y" + ax, name: COMP[c],
                     legendgroup: COMP[c], showlegend: k === 0, marker: {size: 6, color: COLOURS[c]},
                     hovertemplate: COMP[c] + " %{y:.4g} mm at %{x:.4g} N<extra></extra>"});
          data.push({type: "scatter", mode: "lines", x: lx, y: ly, xaxis: "x" + ax, yaxis: "y" + ax, name: COMP[c] + " = (C·F)",
                     legendgroup: COMP[c], showlegend: false, line: {color: COLOURS[c], width: 1.5}, hoverinfo: "skip"});
        }
      });
      return Plotly.react(linEl, data, layout, config);
    }
    function drawResiduals() {
      if (!resEl || !D.residuals) return Promise.resolve();
      const i = +pos.value, L = D.labels.length, data = [];
      for (let c = 0; c < 3; c++) {
        const x = [], y = [], t = [];
        for (let j = 0; j < L; j++) {
          const R = D.residuals[i][j].length;
          D.residuals[i][j].forEach((v, r) => {
            if (v[c] === null) return;
            x.push(j + 1 + (c - 1) * 0.2 + 0.12 * (R > 1 ? r / (R - 1) - 0.5 : 0)); y.push(1000 * v[c]); t.push("load " + (j + 1) + ", repeat " + (r + 1));
          });
        }
        data.push({type: "scatter", mode: "markers", x: x, y: y, text: t, name: COMP[c], marker: {size: 6, color: COLOURS[c]},
                   hovertemplate: "%{text}: " + COMP[c] + " %{y:.3g} µm<extra></extra>"});
      }
      const layout = {
        template: {layout: {paper_bgcolor: "white", plot_bgcolor: "white"}}, height: 340,
        margin: {l: 60, r: 20, t: 50, b: 90}, legend: {orientation: "h", x: 0.75, y: 1.15},
        title: {text: D.positions[i] + ": residuals of d = C·F per load case (µm; each repeat a dot)", x: 0.01, font: {size: 13}},
        xaxis: {tickmode: "array", tickvals: D.labels.map((l, k) => k + 1), ticktext: D.labels.map((l, k) => (k + 1) + ": " + l),
                tickangle: -30, range: [0.4, L + 0.6], gridcolor: "#eee", title: {text: "load case"}},
        yaxis: {title: {text: "µm"}, zeroline: true, zerolinecolor: "#888", gridcolor: "#eee"},
      };
      return Plotly.react(resEl, data, layout, config);
    }
    const redraw = () => Promise.all([draw(), drawLinearity(), drawResiduals()]);
    pos.addEventListener("change", redraw);
    load.addEventListener("change", draw);
    jobs.push(redraw());
    const overview = document.getElementById("fig-loads-overview");
    Promise.all(jobs).then(() => {
      if (overview && overview.on) overview.on("plotly_click", (ev) => {
        const p = ev.points[0];
        pos.value = p.pointIndex[1]; load.value = p.pointIndex[0]; redraw();
      });
    });
  }

  // K table: show only flagged or failed rows.
  const only = document.getElementById("only-flagged");
  if (only) only.addEventListener("change", () => {
    document.querySelectorAll("table.k tbody tr").forEach((tr) => {
      tr.style.display = only.checked && !(tr.classList.contains("flagged") || tr.classList.contains("failed")) ? "none" : "";
    });
  });

  Promise.all(jobs).then(() => { window.stiffmapReady = true; },
                         (e) => { console.error("stiffmap report: a figure failed to render", e); window.stiffmapReady = false; });
})();
"""
