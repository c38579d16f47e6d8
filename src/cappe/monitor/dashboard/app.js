/* cappe monitor dashboard: reads the JSON API of `cappe monitor serve` and draws inline SVG charts.
 *
 * Self-contained (no libraries, no network access beyond this server). Every string from the store is inserted
 * with textContent or setAttribute, never as HTML.
 */
"use strict";

(() => {
  const SVGNS = "http://www.w3.org/2000/svg";
  const DASH = "\u2013";
  const MINUS = "\u2212";
  const MODE_COLOURS = ["#2563eb", "#d97706", "#059669", "#7c3aed", "#db2777", "#0891b2", "#65a30d", "#dc2626"];

  const state = {
    machine: null,   // selected machine id
    frf: null,       // last /frf answer
    frfOutput: null, // selected output name
    frfInput: null,  // selected input name
    token: 0,        // newest load; older answers are dropped
    generation: 0,   // completed renders (tests wait on it)
  };

  // ------------------------------------------------------------------------------------------ DOM helpers

  function setAttrs(node, attrs) {
    for (const [key, value] of Object.entries(attrs || {})) {
      if (value === null || value === undefined || value === false) continue;
      if (key === "text") node.textContent = String(value);
      else if (key === "class") node.setAttribute("class", value);
      else if (key === "on") for (const [ev, fn] of Object.entries(value)) node.addEventListener(ev, fn);
      else node.setAttribute(key, value === true ? "" : String(value));
    }
    return node;
  }

  function append(node, children) {
    for (const child of children) {
      if (child === null || child === undefined || child === false) continue;
      node.append(typeof child === "string" ? document.createTextNode(child) : child);
    }
    return node;
  }

  /** An HTML element; strings among the children become text nodes. */
  function h(tag, attrs, ...children) {
    return append(setAttrs(document.createElement(tag), attrs), children);
  }

  /** An SVG element. */
  function s(tag, attrs, ...children) {
    return append(setAttrs(document.createElementNS(SVGNS, tag), attrs), children);
  }

  const byId = (id) => document.getElementById(id);

  // ------------------------------------------------------------------------------------------ formatting

  function isNum(v) {
    return typeof v === "number" && Number.isFinite(v);
  }

  function fmt(v, digits) {
    if (!isNum(v)) return DASH;
    const text = Math.abs(v) >= 1e5 || (v !== 0 && Math.abs(v) < 1e-4) ? v.toExponential(digits - 1) : v.toPrecision(digits);
    return text.replace("-", MINUS);
  }

  /** Short form for labels: at most 3 significant digits, no trailing zeros (0.25, 1.5, 1200). */
  function fmtShort(v) {
    return isNum(v) ? String(Number(v.toPrecision(3))).replace("-", MINUS) : DASH;
  }

  function fmtPercent(v, digits = 1, signed = true) {
    if (!isNum(v)) return DASH;
    const text = (100 * v).toFixed(digits);
    const sign = signed && v > 0 ? "+" : "";
    return (sign + text).replace("-", MINUS) + "\u00a0%";
  }

  function pad2(n) {
    return String(n).padStart(2, "0");
  }

  const MONTHS = ["Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec"];

  function fmtTime(iso) {
    if (!iso) return DASH;
    const d = new Date(iso);
    if (Number.isNaN(d.getTime())) return String(iso);
    return `${d.getUTCFullYear()}-${pad2(d.getUTCMonth() + 1)}-${pad2(d.getUTCDate())} ` +
      `${pad2(d.getUTCHours())}:${pad2(d.getUTCMinutes())}`;
  }

  function capitalize(text) {
    return text ? text.charAt(0).toUpperCase() + text.slice(1) : text;
  }

  function severityKey(severity) {
    if (severity === null || severity === undefined) return "none";
    if (severity === "tolerable") return "ok";
    if (severity === "conditionally tolerable") return "warn";
    return "bad";
  }

  // ------------------------------------------------------------------------------------------ API

  async function api(path, options) {
    const response = await fetch(path, Object.assign({ cache: "no-store", headers: { Accept: "application/json" } },
      options || {}));
    let body = null;
    try {
      body = await response.json();
    } catch (err) {
      body = null;
    }
    if (!response.ok) {
      throw new Error((body && body.error) || `${response.status} ${response.statusText} (${path})`);
    }
    return body;
  }

  const machinePath = (machine, view) => `api/machine/${encodeURIComponent(machine)}/${view}`;

  function showError(message) {
    const banner = byId("error-banner");
    banner.textContent = message;
    banner.hidden = !message;
    if (message) document.body.dataset.state = "error";
  }

  // ------------------------------------------------------------------------------------------ charts

  function niceStep(span, count) {
    const raw = span / Math.max(count, 1);
    const mag = Math.pow(10, Math.floor(Math.log10(raw)));
    const norm = raw / mag;
    const nice = norm <= 1 ? 1 : norm <= 2 ? 2 : norm <= 2.5 ? 2.5 : norm <= 5 ? 5 : 10;
    return nice * mag;
  }

  function linearTicks(d0, d1, count) {
    const step = niceStep(d1 - d0, count);
    const ticks = [];
    for (let v = Math.ceil(d0 / step - 1e-9) * step; v <= d1 + step * 1e-9; v += step) {
      ticks.push(Math.abs(v) < step * 1e-9 ? 0 : v);
    }
    let decimals = 0;
    while (decimals < 8 && Math.abs(Math.round(step * 10 ** decimals) - step * 10 ** decimals) > 1e-6) decimals += 1;
    return ticks.map((v) => ({ v, label: v.toFixed(decimals).replace("-", MINUS) }));
  }

  const SUPERSCRIPT = { "-": "\u207b", 0: "\u2070", 1: "\u00b9", 2: "\u00b2", 3: "\u00b3", 4: "\u2074", 5: "\u2075",
    6: "\u2076", 7: "\u2077", 8: "\u2078", 9: "\u2079" };

  function logTicks(d0, d1) {
    const lo = Math.floor(Math.log10(d0));
    const hi = Math.ceil(Math.log10(d1));
    const ticks = [];
    const multipliers = hi - lo <= 2 ? [1, 2, 5] : [1];
    for (let e = lo; e <= hi; e++) {
      for (const m of multipliers) {
        const v = m * Math.pow(10, e);
        if (v < d0 * (1 - 1e-9) || v > d1 * (1 + 1e-9)) continue;
        const exp = String(e).split("").map((c) => SUPERSCRIPT[c]).join("");
        ticks.push({ v, label: m === 1 ? `10${exp}` : `${m}\u00b710${exp}`, minor: m !== 1 });
      }
    }
    return ticks;
  }

  const MINUTE = 60e3;
  const HOUR = 60 * MINUTE;
  const DAY = 24 * HOUR;
  const TIME_STEPS = [MINUTE, 5 * MINUTE, 15 * MINUTE, 30 * MINUTE, HOUR, 3 * HOUR, 6 * HOUR, 12 * HOUR, DAY,
    2 * DAY, 7 * DAY, 14 * DAY, 30 * DAY, 91 * DAY, 182 * DAY, 365 * DAY];

  function timeTicks(d0, d1, count) {
    const step = TIME_STEPS.find((st) => (d1 - d0) / st <= count) || TIME_STEPS[TIME_STEPS.length - 1];
    const ticks = [];
    for (let v = Math.ceil(d0 / step) * step; v <= d1; v += step) {
      const d = new Date(v);
      const midnight = d.getUTCHours() === 0 && d.getUTCMinutes() === 0;
      const label = step >= DAY || midnight
        ? `${MONTHS[d.getUTCMonth()]} ${d.getUTCDate()}`
        : `${pad2(d.getUTCHours())}:${pad2(d.getUTCMinutes())}`;
      ticks.push({ v, label });
    }
    return ticks;
  }

  function extent(values, fallback) {
    let lo = Infinity;
    let hi = -Infinity;
    for (const v of values) {
      if (!isNum(v)) continue;
      if (v < lo) lo = v;
      if (v > hi) hi = v;
    }
    return lo <= hi ? [lo, hi] : fallback;
  }

  /** Points with both coordinates usable, split into runs at gaps. */
  function runs(xs, ys, ok) {
    const out = [];
    let run = [];
    for (let i = 0; i < xs.length; i++) {
      if (ok(xs[i], ys[i])) run.push([xs[i], ys[i]]);
      else if (run.length) {
        out.push(run);
        run = [];
      }
    }
    if (run.length) out.push(run);
    return out;
  }

  /**
   * An SVG chart. spec: {width, height, margin, x: {type, domain, label}, y: {type, domain, label}, layers, testid,
   * legend: [{cls, label, shape}]}; layer types: hband, hline, band, line, points, labels.
   */
  function plot(spec) {
    const W = spec.width;
    const H = spec.height;
    const m = Object.assign({ top: 12, right: 14, bottom: 34, left: 54 }, spec.margin || {});
    const hasLegend = Boolean(spec.legend && spec.legend.length);
    if (hasLegend) m.top += 18; // the legend sits above the frame, clear of the data
    const x0 = m.left;
    const x1 = W - m.right;
    const y0 = H - m.bottom;
    const y1 = m.top;
    const xLog = spec.x.type === "log";
    const yLog = spec.y.type === "log";
    const tx = (v) => (xLog ? Math.log10(v) : v);
    const ty = (v) => (yLog ? Math.log10(v) : v);
    const [xd0, xd1] = spec.x.domain.map(tx);
    const [yd0, yd1] = spec.y.domain.map(ty);
    const sx = (v) => x0 + ((tx(v) - xd0) / (xd1 - xd0 || 1)) * (x1 - x0);
    const sy = (v) => y0 + ((ty(v) - yd0) / (yd1 - yd0 || 1)) * (y1 - y0);
    const okX = (v) => isNum(v) && (!xLog || v > 0);
    const okY = (v) => isNum(v) && (!yLog || v > 0);
    const clampY = (v) => Math.max(y1, Math.min(y0, v));

    const root = s("svg", { viewBox: `0 0 ${W} ${H}`, class: "plot", role: "img", "data-testid": spec.testid,
      "aria-label": spec.title || "chart" });
    const clipId = `clip-${Math.random().toString(36).slice(2)}`;
    root.append(s("defs", {}, s("clipPath", { id: clipId }, s("rect", { x: x0, y: y1, width: x1 - x0, height: y0 - y1 }))));

    // grid and axes
    const grid = s("g", { class: "grid" });
    const axes = s("g", { class: "axes" });
    const yTicks = yLog ? logTicks(...spec.y.domain) : linearTicks(...spec.y.domain, spec.y.ticks || 4);
    for (const t of yTicks) {
      const y = sy(t.v);
      grid.append(s("line", { x1: x0, x2: x1, y1: y, y2: y, class: t.minor ? "minor" : null }));
      axes.append(s("text", { x: x0 - 6, y: y + 3.5, class: "tick", "text-anchor": "end", text: t.label }));
    }
    let xTicks;
    if (spec.x.type === "time") xTicks = timeTicks(...spec.x.domain, spec.x.ticks || 4);
    else if (xLog) xTicks = logTicks(...spec.x.domain);
    else xTicks = linearTicks(...spec.x.domain, spec.x.ticks || 5);
    for (const t of xTicks) {
      const x = sx(t.v);
      grid.append(s("line", { x1: x, x2: x, y1: y0, y2: y1, class: "vertical" }));
      axes.append(s("text", { x, y: y0 + 15, class: "tick", "text-anchor": "middle", text: t.label }));
    }
    axes.append(s("rect", { x: x0, y: y1, width: x1 - x0, height: y0 - y1, class: "frame" }));
    if (spec.x.label) {
      axes.append(s("text", { x: (x0 + x1) / 2, y: H - 4, class: "axis-label", "text-anchor": "middle", text: spec.x.label }));
    }
    if (spec.y.label) {
      axes.append(s("text", { x: 12, y: (y0 + y1) / 2, class: "axis-label", "text-anchor": "middle",
        transform: `rotate(-90 12 ${(y0 + y1) / 2})`, text: spec.y.label }));
    }
    root.append(grid);

    const data = s("g", { "clip-path": `url(#${clipId})` });
    const notes = s("g", { class: "notes" });
    for (const layer of spec.layers) {
      const cls = layer.cls;
      if (layer.type === "hband") {
        if (!okY(layer.lo) || !okY(layer.hi)) continue;
        const top = clampY(sy(layer.hi));
        const bottom = clampY(sy(layer.lo));
        data.append(s("rect", { x: x0, y: top, width: x1 - x0, height: Math.max(bottom - top, 0.5), class: cls },
          layer.title ? s("title", { text: layer.title }) : null));
      } else if (layer.type === "hline") {
        if (!okY(layer.y)) continue;
        data.append(s("line", { x1: x0, x2: x1, y1: sy(layer.y), y2: sy(layer.y), class: cls }));
      } else if (layer.type === "band") {
        const idx = layer.x.map((_, i) => i).filter((i) => okX(layer.x[i]) && okY(layer.lo[i]) && okY(layer.hi[i]));
        if (idx.length < 2) continue;
        const upper = idx.map((i) => `${sx(layer.x[i]).toFixed(2)},${sy(layer.hi[i]).toFixed(2)}`);
        const lower = idx.slice().reverse().map((i) => `${sx(layer.x[i]).toFixed(2)},${sy(layer.lo[i]).toFixed(2)}`);
        data.append(s("polygon", { points: upper.concat(lower).join(" "), class: cls }));
      } else if (layer.type === "line") {
        for (const run of runs(layer.x, layer.y, (a, b) => okX(a) && okY(b))) {
          if (run.length < 2) continue;
          const points = run.map(([a, b]) => `${sx(a).toFixed(2)},${sy(b).toFixed(2)}`).join(" ");
          data.append(s("polyline", { points, class: cls, stroke: layer.colour || null }));
        }
      } else if (layer.type === "points") {
        layer.x.forEach((a, i) => {
          const b = layer.y[i];
          if (!okX(a) || !okY(b)) return;
          const cx = sx(a);
          const cy = sy(b);
          const r = layer.r || 2.5;
          const title = layer.titles ? s("title", { text: layer.titles[i] }) : null;
          const attrs = Object.assign({ class: cls, fill: layer.colour || null }, layer.attrs ? layer.attrs(i) : {});
          let mark;
          if (layer.shape === "diamond") {
            mark = s("path", Object.assign(attrs, { d: `M${cx},${cy - r}L${cx + r},${cy}L${cx},${cy + r}L${cx - r},${cy}Z` }), title);
          } else if (layer.shape === "target") {
            mark = s("g", attrs, s("circle", { cx, cy, r, class: "target-ring", stroke: layer.colour || null }),
              s("circle", { cx, cy, r: r * 0.38, class: "target-core", fill: layer.colour || null }), title);
          } else {
            mark = s("circle", Object.assign(attrs, { cx, cy, r }), title);
          }
          data.append(mark);
        });
      } else if (layer.type === "labels") {
        layer.x.forEach((a, i) => {
          const b = layer.y[i];
          if (!okX(a) || !okY(b)) return;
          notes.append(s("text", { x: sx(a) + (layer.dx || 0), y: sy(b) + (layer.dy || 0), class: cls,
            "text-anchor": layer.anchor || "start", text: layer.text[i] }));
        });
      }
    }
    root.append(data, axes, notes);

    if (hasLegend) {
      const legend = s("g", { class: "chart-legend" });
      let lx = x1;
      const ly = y1 - 7;
      for (const item of spec.legend.slice().reverse()) {
        const width = 7 * item.label.length + 22;
        lx -= width;
        const swatch = item.shape === "line"
          ? s("line", { x1: lx, x2: lx + 14, y1: ly - 3, y2: ly - 3, class: item.cls, stroke: item.colour || null })
          : s("circle", { cx: lx + 7, cy: ly - 3, r: 3.5, class: item.cls, fill: item.colour || null });
        legend.append(swatch, s("text", { x: lx + 18, y: ly, class: "legend-text", text: item.label }));
      }
      root.append(legend);
    }
    return root;
  }

  /** Width in px a chart gets inside a container (its viewBox then maps 1:1 to the screen). */
  function fitWidth(container, fallback) {
    const width = Math.floor(container.clientWidth);
    return width > 120 ? width : fallback;
  }

  function placeholder(text) {
    return h("div", { class: "chart-empty", text });
  }

  function padDomain([lo, hi], fraction, minSpan) {
    let span = hi - lo;
    if (span < minSpan) {
      const mid = (lo + hi) / 2;
      lo = mid - minSpan / 2;
      hi = mid + minSpan / 2;
      span = minSpan;
    }
    return [lo - fraction * span, hi + fraction * span];
  }

  // ------------------------------------------------------------------------------------------ status

  function renderStatus(status, alarms) {
    const header = byId("status");
    const key = severityKey(status.worst_severity);
    header.dataset.severity = key;
    header.dataset.worst = status.worst_severity || "none";
    byId("worst-severity").textContent = status.worst_severity ? capitalize(status.worst_severity) : "No active alarms";
    const outside = status.components.filter((c) => isNum(c.value) && c.baseline_band &&
      isNum(c.baseline_band[0]) && isNum(c.baseline_band[1]) && (c.value < c.baseline_band[0] || c.value > c.baseline_band[1]));
    let sub;
    if (status.active_alarms > 0) {
      const labels = [...new Set(alarms.alarms.filter((a) => !a.acknowledged).map((a) => capitalize(a.component_label)))];
      sub = `${status.active_alarms} unacknowledged alarm${status.active_alarms === 1 ? "" : "s"}: ${labels.join(", ")}`;
    } else if (!status.latest_measurement) {
      sub = "No measurements recorded yet";
    } else if (!status.has_baseline) {
      sub = "No baseline stored yet: run the baseline step";
    } else if (outside.length) {
      sub = `Outside the baseline band: ${outside.map((c) => c.label).join(", ")}`;
    } else {
      sub = "All components within the baseline band";
    }
    byId("status-sub").textContent = sub;
    byId("n-measurements").textContent = String(status.n_measurements);
    byId("latest-timestamp").textContent = status.latest_measurement ? fmtTime(status.latest_measurement.timestamp) : DASH;
    byId("active-alarms").textContent = String(status.active_alarms);
    byId("latest-csf").textContent = fmt(status.features ? status.features.csf : null, 3);
    byId("machine-model").textContent = status.model ? String(status.model) : "";
  }

  // ------------------------------------------------------------------------------------------ components and trends

  function trendChart(component, width) {
    const fast = component.fast;
    const slow = component.slow;
    const base = component.baseline;
    const tFast = fast.timestamp.map((t) => Date.parse(t));
    const tSlow = slow.timestamp.map((t) => Date.parse(t));
    if (!tFast.length && !tSlow.length) return placeholder("No estimates yet");
    const lo = fast.value.map((v, i) => (isNum(v) && isNum(fast.std[i]) ? v - 2 * fast.std[i] : null));
    const hi = fast.value.map((v, i) => (isNum(v) && isNum(fast.std[i]) ? v + 2 * fast.std[i] : null));
    const band = base.band || [null, null];
    const yValues = fast.value.concat(slow.value, lo, hi, band, [base.mean]);
    const yDomain = padDomain(extent(yValues, [0.9, 1.1]), 0.08, 0.01);
    const xDomain = padDomain(extent(tFast.concat(tSlow), [0, 1]), 0.03, 2 * HOUR);
    const tip = (times, values, stds, path) => values.map((v, i) =>
      `${fmtTime(times[i])} UTC, ${path}: ${fmt(v, 4)} \u00b1 ${fmt(stds[i], 2)}`);
    return plot({
      width, height: 160, margin: { left: 46, bottom: 24, top: 10, right: 10 },
      testid: `trend-${component.name}`, title: `${component.label} stiffness factor over time`,
      x: { type: "time", domain: xDomain, ticks: 4 },
      y: { type: "linear", domain: yDomain, ticks: 4 },
      layers: [
        { type: "hband", lo: band[0], hi: band[1], cls: "baseline-band",
          title: `baseline band ${fmt(band[0], 4)} \u2026 ${fmt(band[1], 4)}` },
        { type: "hline", y: base.mean, cls: "baseline-mean" },
        { type: "band", x: tFast, lo, hi, cls: "unc-band" },
        { type: "line", x: tFast, y: fast.value, cls: "fast-line" },
        { type: "points", x: tFast, y: fast.value, cls: "fast-point", r: 2,
          titles: tip(fast.timestamp, fast.value, fast.std, "fast") },
        { type: "points", x: tSlow, y: slow.value, cls: "slow-point", r: 4, shape: "diamond",
          titles: tip(slow.timestamp, slow.value, slow.std, "slow") },
      ],
    });
  }

  function renderComponents(status, trends) {
    const grid = byId("components");
    grid.replaceChildren();
    const n = status.components.length;
    grid.className = `component-grid ${n === 2 || n === 4 ? `cols-${n}` : n >= 7 ? "cols-4" : ""}`.trim();
    const trendOf = new Map(trends.components.map((c) => [c.name, c]));
    if (!status.components.length) {
      grid.append(h("div", { class: "empty", text: "No components configured and no estimates recorded." }));
    }
    for (const c of status.components) {
      const band = c.baseline_band;
      const outside = isNum(c.value) && band && isNum(band[0]) && isNum(band[1]) && (c.value < band[0] || c.value > band[1]);
      const changeCls = outside ? "change change-bad" : "change";
      const trend = trendOf.get(c.name);
      const card = h("article", { class: `card component-card${outside ? " out-of-band" : ""}`,
        "data-testid": `component-${c.name}`, "data-component": c.name },
      h("div", { class: "card-head" },
        h("h3", { text: capitalize(c.label) }),
        h("span", { class: "component-name", text: c.name })),
      h("div", { class: "reading" },
        h("span", { class: "value", "data-testid": `latest-${c.name}`, text: c.value_text }),
        h("span", { class: "std" }, "\u00b1\u00a0", h("span", { "data-testid": `std-${c.name}`, text: c.std_text })),
        h("span", { class: changeCls, "data-testid": `change-${c.name}`, title: "change against the baseline mean",
          text: isNum(c.change) ? fmtPercent(c.change) : "" })),
      h("div", { class: "baseline-line" },
        isNum(c.baseline_mean)
          ? `baseline ${fmt(c.baseline_mean, 4)} \u00b1 ${fmt(c.baseline_std, 2)}` +
            (isNum(c.z) ? ` \u00b7 z\u00a0=\u00a0${fmt(c.z, 2)}` : "")
          : "no baseline"),
      h("div", { class: "chart" }));
      grid.append(card);
      const holder = card.querySelector(".chart");
      holder.append(trend ? trendChart(trend, fitWidth(holder, 360)) : placeholder("No estimates yet"));
    }

    const csf = trends.csf;
    const csfCard = byId("csf-card");
    const tCsf = csf.timestamp.map((t) => Date.parse(t));
    csfCard.hidden = !csf.value.some(isNum);
    if (!csfCard.hidden) {
      byId("csf-chart").replaceChildren(plot({
        width: fitWidth(byId("csf-chart"), 1150), height: 150, margin: { left: 46, bottom: 24, top: 10, right: 12 }, testid: "csf-plot",
        title: "FRF correlation with the baseline over time",
        x: { type: "time", domain: padDomain(extent(tCsf, [0, 1]), 0.01, 2 * HOUR), ticks: 8 },
        y: { type: "linear", domain: padDomain(extent(csf.value.concat([1]), [0, 1]), 0.08, 0.02), ticks: 3 },
        layers: [
          { type: "line", x: tCsf, y: csf.value, cls: "csf-line" },
          { type: "points", x: tCsf, y: csf.value, cls: "csf-point", r: 2,
            titles: csf.value.map((v, i) => `${fmtTime(csf.timestamp[i])} UTC: CSF ${fmt(v, 4)}`) },
        ],
      }));
    }
  }

  // ------------------------------------------------------------------------------------------ alarms

  function diagnosisCell(alarm) {
    const d = alarm.diagnosis || {};
    const cell = h("td", { class: "diagnosis" });
    const label = d.label || d.hypothesis;
    if (label || isNum(d.change)) {
      cell.append(h("div", {},
        label ? h("span", { class: "hypothesis", text: capitalize(String(label)) }) : null,
        isNum(d.change) ? h("span", { class: "muted", text: `${label ? " \u00b7 " : ""}${fmtPercent(d.change)}` }) : null));
    }
    if (d.candidates && typeof d.candidates === "object") {
      const top = Object.entries(d.candidates).filter(([, p]) => isNum(p)).sort((a, b) => b[1] - a[1]).slice(0, 3);
      if (top.length) {
        cell.append(h("div", { class: "candidates muted",
          text: top.map(([name, p]) => `${name} ${fmtPercent(p, 0, false)}`).join(" \u00b7 ") }));
      }
    }
    if (!cell.childNodes.length) cell.textContent = DASH;
    return cell;
  }

  function renderAlarms(answer) {
    const body = byId("alarm-body");
    body.replaceChildren();
    const alarms = answer.alarms;
    byId("no-alarms").hidden = alarms.length > 0;
    const active = alarms.filter((a) => !a.acknowledged).length;
    byId("alarm-summary").textContent = alarms.length ? `${alarms.length} recorded \u00b7 ${active} active` : "";
    for (const alarm of alarms) {
      const key = severityKey(alarm.severity);
      const action = alarm.acknowledged
        ? h("span", { class: "acked", "data-testid": "ack-done", text: "\u2713 acknowledged" })
        : h("button", { type: "button", class: "button button-small", "data-testid": "ack-button",
          "data-alarm-id": alarm.id, text: "Acknowledge", on: { click: (ev) => acknowledge(alarm.id, ev.currentTarget) } });
      body.append(h("tr", { class: alarm.acknowledged ? "acknowledged" : null, "data-testid": "alarm-row",
        "data-alarm-id": alarm.id, "data-acknowledged": String(alarm.acknowledged), "data-severity": alarm.severity },
      h("td", { class: "nowrap", text: fmtTime(alarm.timestamp) }),
      h("td", {}, h("div", { text: capitalize(alarm.component_label) }), h("div", { class: "muted small", text: alarm.component })),
      h("td", {}, h("div", { class: "mono", text: alarm.statistic }),
        h("div", { class: "muted small", "data-testid": "alarm-value", text: `= ${fmt(alarm.value, 4)}` })),
      h("td", {}, h("span", { class: `badge badge-${key}`, "data-testid": "alarm-severity", text: alarm.severity })),
      diagnosisCell(alarm),
      h("td", { class: "num", "data-testid": "alarm-probability", text: alarm.probability_text }),
      h("td", { class: "message", text: alarm.message }),
      h("td", { class: "action" }, action)));
    }
  }

  async function acknowledge(alarmId, button) {
    button.disabled = true;
    button.textContent = "Acknowledging\u2026";
    try {
      await api(`api/alarm/${encodeURIComponent(alarmId)}/acknowledge`, {
        method: "POST", headers: { Accept: "application/json", "Content-Type": "application/json" }, body: "{}" });
      await loadMachine();
    } catch (err) {
      showError(`Could not acknowledge alarm ${alarmId}: ${err.message}`);
      button.disabled = false;
      button.textContent = "Acknowledge";
    }
  }

  // ------------------------------------------------------------------------------------------ FRF

  function fillSelect(select, names, current) {
    select.replaceChildren(...names.map((n) => h("option", { value: n, text: n })));
    const chosen = names.includes(current) ? current : names[0];
    if (chosen !== undefined) select.value = chosen;
    select.disabled = names.length < 2;
    return chosen === undefined ? null : chosen;
  }

  function renderFrf() {
    const answer = state.frf;
    const chart = byId("frf-chart");
    const caption = byId("frf-caption");
    const meas = answer && answer.measurement;
    byId("frf-controls").hidden = !meas;
    if (!meas) {
      fillSelect(byId("frf-output"), [], null);
      fillSelect(byId("frf-input"), [], null);
      caption.textContent = "";
      chart.replaceChildren(placeholder("No FRF stored for this machine."));
      return;
    }
    const o = meas.output_names.indexOf(state.frfOutput);
    const i = meas.input_names.indexOf(state.frfInput);
    const mag = meas.magnitude[o][i];
    const layers = [];
    const legend = [{ label: "latest", cls: "frf-latest", shape: "line" }];
    const base = answer.baseline;
    let baseFreq = [];
    let baseMag = [];
    if (base && base.output_names && base.input_names && base.magnitude) {
      const bo = base.output_names.indexOf(state.frfOutput);
      const bi = base.input_names.indexOf(state.frfInput);
      if (bo >= 0 && bi >= 0) {
        baseFreq = base.freq;
        baseMag = base.magnitude[bo][bi];
        layers.push({ type: "line", x: baseFreq, y: baseMag, cls: "frf-baseline" });
        legend.unshift({ label: "baseline mean", cls: "frf-baseline", shape: "line" });
      }
    }
    layers.push({ type: "line", x: meas.freq, y: mag, cls: "frf-latest" });
    const positive = mag.concat(baseMag).filter((v) => isNum(v) && v > 0);
    if (!positive.length) {
      chart.replaceChildren(placeholder("The FRF has no positive magnitude to show on a log scale."));
      return;
    }
    const [ylo, yhi] = extent(positive, [1e-9, 1]);
    const yDomain = [ylo / 1.6, yhi * 1.6];
    const xDomain = extent(meas.freq.concat(baseFreq), [0, 1]);
    if (xDomain[1] <= xDomain[0]) xDomain[1] = xDomain[0] + 1;
    caption.textContent = `Measurement #${meas.id} \u00b7 ${fmtTime(meas.timestamp)} UTC \u00b7 ` +
      `output ${state.frfOutput} / input ${state.frfInput}` + (legend.length < 2 ? " \u00b7 no baseline FRF for this pair" : "");
    chart.replaceChildren(plot({
      width: fitWidth(chart, 560), height: 320, testid: "frf-plot", title: "FRF magnitude",
      margin: { left: 62, bottom: 36, top: 12, right: 14 },
      x: { type: "linear", domain: xDomain, label: "Frequency (Hz)", ticks: 6 },
      y: { type: "log", domain: yDomain, label: "|H|" },
      layers, legend,
    }));
  }

  function renderFrfAnswer(answer) {
    state.frf = answer;
    const meas = answer.measurement;
    state.frfOutput = fillSelect(byId("frf-output"), meas ? meas.output_names : [], state.frfOutput);
    state.frfInput = fillSelect(byId("frf-input"), meas ? meas.input_names : [], state.frfInput);
    renderFrf();
  }

  // ------------------------------------------------------------------------------------------ frequency-damping map

  function renderMap(answer) {
    const chart = byId("map-chart");
    const caption = byId("map-caption");
    const map = answer.map;
    const current = answer.current;
    const modes = answer.modes || [];
    if (!map && !current) {
      caption.textContent = "";
      chart.replaceChildren(placeholder("No frequency\u2013damping map in the baseline and no modal features yet."));
      return;
    }
    const layers = [];
    const xs = [];
    const ys = [];
    const colour = (j) => MODE_COLOURS[j % MODE_COLOURS.length];
    const parameter = map && map.parameter ? String(map.parameter) : "preload";
    if (map && Array.isArray(map.frequency)) {
      modes.forEach((mode, j) => {
        const f = map.frequency.map((row) => (Array.isArray(row) ? row[j] : null));
        const z = (Array.isArray(map.damping) ? map.damping : []).map((row) => (Array.isArray(row) && isNum(row[j]) ? 100 * row[j] : null));
        xs.push(...f);
        ys.push(...z);
        const p = (map[parameter] || map.preload || []).map(fmtShort);
        layers.push({ type: "line", x: f, y: z, cls: "map-curve", colour: colour(j) });
        layers.push({ type: "points", x: f, y: z, cls: "map-node", colour: colour(j), r: 2.2,
          titles: f.map((fv, k) => `mode ${mode}, ${parameter} ${p[k]}: ${fmt(fv, 4)} Hz, ${fmt(z[k], 3)} %`) });
        const ends = [0, f.length - 1].filter((k, idx, arr) => arr.indexOf(k) === idx);
        layers.push({ type: "labels", x: ends.map((k) => f[k]), y: ends.map((k) => z[k]), text: ends.map((k) => p[k]),
          cls: "map-label", dx: 5, dy: -5 });
      });
    }
    const trail = answer.trail || [];
    modes.forEach((mode, j) => {
      const f = trail.map((pt) => pt.frequency[j]);
      const z = trail.map((pt) => (isNum(pt.damping[j]) ? 100 * pt.damping[j] : null));
      xs.push(...f);
      ys.push(...z);
      layers.push({ type: "points", x: f, y: z, cls: "map-trail", colour: colour(j), r: 2,
        titles: trail.map((pt, k) => `mode ${mode} at ${fmtTime(pt.timestamp)} UTC: ${fmt(f[k], 4)} Hz, ${fmt(z[k], 3)} %`) });
    });
    if (current) {
      const f = current.frequency;
      const z = current.damping.map((v) => (isNum(v) ? 100 * v : null));
      xs.push(...f);
      ys.push(...z);
      layers.push({ type: "points", x: f, y: z, cls: "map-current", shape: "target", r: 7,
        attrs: (j) => ({ "data-testid": "map-current", "data-mode": modes[j] }),
        titles: f.map((fv, j) => `current, mode ${modes[j]}: ${fmt(fv, 4)} Hz, ${fmt(z[j], 3)} %`) });
    }
    const xDomain = padDomain(extent(xs, [0, 1]), 0.06, 1);
    const yDomain = padDomain(extent(ys, [0, 1]), 0.1, 0.05);
    const values = map ? (map[parameter] || map.preload || []).filter(isNum) : [];
    caption.textContent = (map ? `Baseline map over ${parameter} ${fmtShort(Math.min(...values))}` +
      `\u2026${fmtShort(Math.max(...values))} (curve labels)` : "No baseline map") +
      (current ? ` \u00b7 current: measurement #${current.measurement_id}, ${fmtTime(current.timestamp)} UTC` : "");
    const legend = modes.map((mode, j) => ({ label: `mode ${mode}`, cls: "map-swatch", colour: colour(j), shape: "dot" }));
    if (current) legend.push({ label: "current", cls: "legend-current", shape: "dot" });
    const svgChart = plot({
      width: fitWidth(chart, 560), height: 320, testid: "map-plot", title: "frequency-damping map",
      margin: { left: 56, bottom: 36, top: 12, right: 14 },
      x: { type: "linear", domain: xDomain, label: "Natural frequency (Hz)", ticks: 6 },
      y: { type: "linear", domain: yDomain, label: "Damping ratio (%)", ticks: 5 },
      layers, legend,
    });
    // colour each current-point target like its mode
    svgChart.querySelectorAll("[data-testid='map-current']").forEach((node) => {
      const j = modes.indexOf(Number(node.getAttribute("data-mode")));
      node.querySelectorAll(".target-ring").forEach((ring) => ring.setAttribute("stroke", colour(j)));
      node.querySelectorAll(".target-core").forEach((core) => core.setAttribute("fill", colour(j)));
    });
    chart.replaceChildren(svgChart);
  }

  // ------------------------------------------------------------------------------------------ loading

  async function loadMachine() {
    const machine = state.machine;
    if (machine === null) return;
    const token = ++state.token;
    document.body.dataset.state = "loading";
    const [status, trends, alarms, frf, map] = await Promise.all(
      ["status", "trends", "alarms", "frf", "map"].map((view) => api(machinePath(machine, view))));
    if (token !== state.token) return;
    byId("machine-name").textContent = machine;
    renderStatus(status, alarms);
    renderComponents(status, trends);
    renderAlarms(alarms);
    renderFrfAnswer(frf);
    renderMap(map);
    showError("");
    const now = new Date();
    byId("updated").textContent = `Updated ${pad2(now.getHours())}:${pad2(now.getMinutes())}:${pad2(now.getSeconds())}`;
    state.generation += 1;
    document.body.dataset.generation = String(state.generation);
    document.body.dataset.machine = machine;
    document.body.dataset.state = "ready";
  }

  function machineFromHash() {
    const match = /^#machine=(.*)$/.exec(window.location.hash);
    return match ? decodeURIComponent(match[1]) : null;
  }

  async function loadMachines() {
    const answer = await api("api/machines");
    const ids = answer.machines.map((m) => m.id);
    const select = byId("machine-select");
    select.replaceChildren(...answer.machines.map((m) => h("option", { value: m.id,
      text: m.active_alarms ? `${m.id} (${m.active_alarms} active)` : m.id })));
    select.hidden = ids.length < 2;
    byId("machine-name").hidden = ids.length >= 2;
    byId("machine-label").hidden = ids.length === 0;
    byId("empty-store").hidden = ids.length > 0;
    const wanted = [state.machine, machineFromHash()].find((m) => m !== null && ids.includes(m));
    state.machine = wanted !== undefined ? wanted : ids.length ? ids[0] : null;
    if (state.machine === null) {
      document.body.dataset.state = "ready";
      return;
    }
    select.value = state.machine;
  }

  async function refresh() {
    try {
      await loadMachines();
      await loadMachine();
    } catch (err) {
      showError(`Could not load the dashboard: ${err.message}`);
    }
  }

  function init() {
    byId("machine-select").addEventListener("change", (ev) => {
      state.machine = ev.target.value;
      window.history.replaceState(null, "", `#machine=${encodeURIComponent(state.machine)}`);
      loadMachine().catch((err) => showError(`Could not load machine ${state.machine}: ${err.message}`));
    });
    byId("frf-output").addEventListener("change", (ev) => {
      state.frfOutput = ev.target.value;
      renderFrf();
    });
    byId("frf-input").addEventListener("change", (ev) => {
      state.frfInput = ev.target.value;
      renderFrf();
    });
    byId("refresh").addEventListener("click", refresh);
    window.addEventListener("hashchange", () => {
      const m = machineFromHash();
      if (m !== null && m !== state.machine) {
        state.machine = m;
        refresh();
      }
    });
    refresh();
    // a monitoring screen keeps itself current: reload every 30 s (?refresh=N seconds, 0 = never) while visible
    const period = Number(new URLSearchParams(window.location.search).get("refresh") ?? 30);
    if (period > 0) {
      window.setInterval(() => {
        if (!document.hidden) refresh();
      }, 1000 * period);
    }
  }

  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", init);
  else init();
})();
