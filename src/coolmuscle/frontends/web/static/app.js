/* coolmuscle dashboard: one page, one WebSocket, every motor of the chain.
 *
 * The server (coolmuscle.frontends.web) sends "hello" (chain layout, recent log,
 * a first snapshot), then "log" (lines exactly as the host line prints them, with
 * their virtual time), "snap" (every motor's values while something changes) and
 * "tick" (the virtual time, once a second).  Requests carry an id and get a
 * "result".  No build step: plain browser JavaScript, uPlot bundled beside it.
 */
"use strict";

(function () {
  // Ux bits, cml-users-guide.txt 6.6 ?99 ("alarm" bits free the motor, ch. 3 K56/K57).
  const UX_BITS = [
    [1, "position error overflow", true], [2, "over speed", true],
    [4, "overload", true], [8, "in position", false], [16, "free", false],
    [32, "push", false], [64, "over current", true], [128, "temperature", true],
    [256, "push error", false], [512, "emergency stop", false],
  ];
  const MAX_LOG = 2000;
  const MAX_LINE = 512;
  const MAX_BANK = 48 * 1024;
  const REQUEST_TIMEOUT_MS = 10000;

  const $ = (id) => document.getElementById(id);
  const state = {
    ws: null, token: null, nextId: 1, pending: new Map(), motors: [], fields: [],
    io: { inputs: 6, outputs: 4 }, cards: new Map(), series: new Map(),
    history: [], historyAt: -1, lastTime: 0, retry: 0, hello: false, dirty: false,
    reconnectTimer: null,
  };

  // -- connection ---------------------------------------------------------------
  function setConn(text, ok) {
    $("conn-text").textContent = text;
    $("conn-dot").className = "dot " + (ok ? "on" : "off");
  }

  function readToken() {
    const m = /(?:^|[#&])token=([^&]+)/.exec(location.hash);
    if (m) {
      sessionStorage.setItem("coolmuscle-token", decodeURIComponent(m[1]));
      history.replaceState(null, "", location.pathname);
    }
    return sessionStorage.getItem("coolmuscle-token");
  }

  async function boot() {
    state.token = readToken();
    let info = { token_required: false };
    try {
      const r = await fetch("/api/info", { cache: "no-store" });
      info = await r.json();
    } catch (e) {
      setConn("simulator not reachable, retrying…", false);
      scheduleReconnect();
      return;
    }
    if (info.title) $("title").textContent = info.title;
    if (info.token_required && !state.token) {
      askToken();
      return;
    }
    connect();
  }

  function askToken() {
    const dlg = $("token-dialog");
    $("token-form").onsubmit = () => {
      state.token = $("token-input").value.trim();
      sessionStorage.setItem("coolmuscle-token", state.token);
      setDownloadLinks();
      connect();
    };
    if (!dlg.open) dlg.showModal();
  }

  function wsUrl() {
    const proto = location.protocol === "https:" ? "wss:" : "ws:";
    const q = state.token ? "?token=" + encodeURIComponent(state.token) : "";
    return proto + "//" + location.host + "/ws" + q;
  }

  function connect() {
    clearTimeout(state.reconnectTimer);
    setDownloadLinks();
    let ws;
    try {
      ws = new WebSocket(wsUrl());
    } catch (e) {
      scheduleReconnect();
      return;
    }
    state.ws = ws;
    state.hello = false;
    ws.onopen = () => setConn("connected", true);
    ws.onmessage = (ev) => { for (const frame of String(ev.data).split("\n")) onFrame(frame); };
    ws.onclose = (ev) => {
      if (state.ws !== ws) return;
      state.ws = null;
      failPending("the connection closed before an answer came");
      if (ev.code === 1009) {
        note("cml-note", "the simulator refused a message that was too large");
      }
      if (!state.hello && state.token && ev.code === 1006 && state.retry > 2) {
        // a wrong token is refused before the socket opens
        fetch("/api/info").then((r) => r.json()).then((info) => {
          if (info.token_required) { sessionStorage.removeItem("coolmuscle-token");
            state.token = null; askToken(); }
        }).catch(() => {});
      }
      scheduleReconnect();
    };
    ws.onerror = () => {};
  }

  function scheduleReconnect() {
    state.retry += 1;
    const delay = Math.min(5000, 250 * Math.pow(2, Math.min(state.retry, 5)));
    setConn("disconnected, reconnecting in " + (delay / 1000).toFixed(1) + " s…", false);
    clearTimeout(state.reconnectTimer);
    state.reconnectTimer = setTimeout(boot, delay);
  }

  function failPending(why) {
    for (const [, p] of state.pending) { clearTimeout(p.timer); p.resolve({ ok: false, error: why }); }
    state.pending.clear();
  }

  function request(kind, body) {
    return new Promise((resolve) => {
      const ws = state.ws;
      if (!ws || ws.readyState !== WebSocket.OPEN) {
        resolve({ ok: false, error: "not connected to the simulator" });
        return;
      }
      const id = state.nextId++;
      const timer = setTimeout(() => {
        state.pending.delete(id);
        resolve({ ok: false, error: "no answer from the simulator" });
      }, REQUEST_TIMEOUT_MS);
      state.pending.set(id, { resolve, timer });
      ws.send(JSON.stringify(Object.assign({ t: kind, id }, body)));
    });
  }

  function onFrame(text) {
    let msg;
    try { msg = JSON.parse(text); } catch (e) { return; }
    if (msg.t === "hello") onHello(msg);
    else if (msg.t === "snap") onSnap(msg);
    else if (msg.t === "log") onLog(msg.lines, msg.dropped);
    else if (msg.t === "tick") { setTime(msg.time); state.dirty = true; }
    else if (msg.t === "recording") showRecording(msg.on);
    else if (msg.t === "result") {
      const p = state.pending.get(msg.id);
      if (p) { clearTimeout(p.timer); state.pending.delete(msg.id); p.resolve(msg); }
      else if (!msg.ok) note("cml-note", msg.error);
    }
  }

  function onHello(msg) {
    state.hello = true;
    state.retry = 0;
    setConn("connected", true);
    const same = msg.motors.join(",") === state.motors.join(",");
    state.fields = msg.fields;
    state.io = msg.io;
    if (!same || !state.cards.size) buildMotors(msg.motors);
    if (!$("faults").childElementCount) buildFaults(msg.faults);
    if (msg.time < state.lastTime) resetSeries();   // a restarted simulator
    $("log").textContent = "";
    onLog(msg.log, 0);
    onSnap(msg.snap);
    showRecording(msg.recording);
  }

  function showRecording(on) {
    $("record-state").textContent = on ? "recording (since it was started)" : "not recording";
    $("record").disabled = !!on;
  }

  // -- motor cards ----------------------------------------------------------------
  function buildMotors(ids) {
    state.motors = ids.slice();
    const box = $("motors");
    box.textContent = "";
    state.cards.clear();
    for (const sel of ["cml-motor", "bank-motor", "fault-motor", "xy-x", "xy-y"]) {
      const el = $(sel);
      el.textContent = "";
      for (const id of ids) el.add(new Option("ID" + id, String(id)));
    }
    if (ids.length > 1) $("xy-y").value = String(ids[1]);
    for (const id of ids) box.appendChild(buildCard(id));
    resetSeries();
  }

  function buildCard(id) {
    const node = $("card-tpl").content.firstElementChild.cloneNode(true);
    const h = node.querySelector(".card-h");
    h.textContent = "ID" + id;
    h.id = "card-h-" + id;
    node.setAttribute("aria-labelledby", h.id);
    const ref = (cls, testid) => {
      const el = node.querySelector(cls);
      if (testid) el.dataset.testid = testid;
      return el;
    };
    const card = {
      node,
      position: ref(".v-position", "position-" + id), target: ref(".v-target", "target-" + id),
      speed: ref(".v-speed", "speed-" + id), torque: ref(".v-torque", "torque-" + id),
      temperature: ref(".v-temperature"), pe: ref(".v-pe"), voltage: ref(".v-voltage"),
      aout: ref(".v-aout"), status: ref(".status", "status-" + id),
      inputs: [], outputs: [], analog: node.querySelector(".a-range"),
      analogValue: node.querySelector(".a-value"), chartBox: ref(".chart", "chart-" + id),
      last: null,
    };
    const ins = node.querySelector(".inputs");
    ins.setAttribute("aria-label", "Inputs of ID" + id);
    for (let n = 1; n <= state.io.inputs; n++) {
      const b = document.createElement("button");
      b.type = "button";
      b.className = "toggle";
      b.textContent = "IN" + n;
      b.dataset.testid = "input-" + id + "-" + n;
      b.setAttribute("aria-pressed", "false");
      b.setAttribute("aria-label", "Input " + n + " of ID" + id);
      b.addEventListener("click", () => toggleInput(id, n, b));
      ins.appendChild(b);
      card.inputs.push(b);
    }
    const outs = node.querySelector(".outputs");
    outs.setAttribute("aria-label", "Outputs of ID" + id);
    for (let n = 1; n <= state.io.outputs; n++) {
      const l = document.createElement("span");
      l.className = "lamp";
      l.textContent = "OUT" + n;
      l.dataset.testid = "output-" + id + "-" + n;
      l.setAttribute("role", "img");
      l.setAttribute("aria-label", "Output " + n + " of ID" + id + " off");
      outs.appendChild(l);
      card.outputs.push(l);
    }
    card.analog.setAttribute("aria-label", "Analog input of ID" + id + " (0..1023)");
    card.analog.dataset.testid = "analog-" + id;
    card.analog.addEventListener("input", () => { card.analogValue.textContent = card.analog.value; });
    card.analog.addEventListener("change", async () => {
      const r = await request("analog", { motor: id, counts: Number(card.analog.value) });
      if (!r.ok) note("cml-note", r.error);
    });
    state.cards.set(id, card);
    return node;
  }

  async function toggleInput(id, n, button) {
    if (button.getAttribute("aria-busy") === "true") return;
    const on = button.getAttribute("aria-pressed") !== "true";
    button.setAttribute("aria-busy", "true");     // not disabled: that would drop the focus
    const r = await request("input", { motor: id, n, on });
    button.removeAttribute("aria-busy");
    if (!r.ok) { note("cml-note", r.error); return; }
    showBits(state.cards.get(id).inputs, r.inputs, "Input", id);
  }

  function statusText(ux) {
    const names = UX_BITS.filter(([bit]) => ux & bit).map(([, name]) => name);
    return "Ux=" + ux + " " + (names.length ? names.join(", ") : "moving");
  }

  function showBits(elements, word, what, id) {
    elements.forEach((el, i) => {
      const on = ((word >> i) & 1) === 1;
      if (el.tagName === "BUTTON") el.setAttribute("aria-pressed", String(on));
      else el.setAttribute("aria-label", what + " " + (i + 1) + " of ID" + id + (on ? " on" : " off"));
      el.classList.toggle("on", on);
    });
  }

  function onSnap(msg) {
    if (!msg || !msg.m) return;
    setTime(msg.time);
    const t = msg.time / 1e9;
    const f = state.fields;
    const at = (name) => f.indexOf(name);
    const idx = {
      id: at("id"), position: at("position"), target: at("target"), speed: at("speed"),
      torque: at("torque"), status: at("status"), inputs: at("inputs"), outputs: at("outputs"),
      temperature: at("temperature"), analog: at("analog"), aout: at("analog_out"),
      voltage: at("voltage"), pe: at("position_error"),
    };
    for (const row of msg.m) {
      const id = row[idx.id];
      const card = state.cards.get(id);
      if (!card) continue;
      card.position.textContent = row[idx.position];
      card.target.textContent = row[idx.target];
      card.speed.textContent = row[idx.speed];
      card.torque.textContent = row[idx.torque];
      card.temperature.textContent = row[idx.temperature];
      card.pe.textContent = row[idx.pe];
      card.voltage.textContent = (row[idx.voltage] / 10).toFixed(1);
      card.aout.textContent = row[idx.aout];
      const ux = row[idx.status];
      card.status.textContent = statusText(ux);
      const alarm = UX_BITS.some(([bit, , isAlarm]) => isAlarm && (ux & bit));
      card.status.classList.toggle("alarm", alarm);
      card.node.classList.toggle("alarm", alarm);
      showBits(card.inputs, row[idx.inputs], "Input", id);
      showBits(card.outputs, row[idx.outputs], "Output", id);
      if (document.activeElement !== card.analog) {
        card.analog.value = row[idx.analog];
        card.analogValue.textContent = row[idx.analog];
      }
      pushSample(id, t, row[idx.position], row[idx.target], row[idx.speed], row[idx.torque]);
    }
    state.dirty = true;
  }

  function setTime(ns) {
    state.lastTime = ns;
    $("vtime").textContent = (ns / 1e9).toFixed(3);
  }

  // -- charts --------------------------------------------------------------------
  function resetSeries() {
    for (const id of state.motors) {
      const old = state.series.get(id);
      if (old) { old.top.destroy(); old.bottom.destroy(); }
      const card = state.cards.get(id);
      if (!card) continue;
      const data = [[], [], [], [], []];
      const width = Math.max(200, card.chartBox.clientWidth || 300);
      const top = new uPlot(chartOpts(width, 130, [
        { label: "position", stroke: "#1f6feb", width: 2 },
        { label: "target", stroke: "#d29922", width: 1, dash: [6, 4],
          paths: uPlot.paths.stepped({ align: 1 }) },
      ], "pulses"), [data[0], data[1], data[2]], card.chartBox);
      const bottom = new uPlot(chartOpts(width, 110, [
        { label: "speed", stroke: "#2da44e", width: 1.5 },
        { label: "torque %", stroke: "#cf222e", width: 1.5, scale: "%" },
      ], "speed"), [data[0], data[3], data[4]], card.chartBox);
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

  function pushSample(id, t, pos, tgt, spd, trq) {
    const s = state.series.get(id);
    if (!s) return;
    const d = s.data;
    if (d[0].length && t < d[0][d[0].length - 1]) { d.forEach((a) => { a.length = 0; }); }
    d[0].push(t); d[1].push(pos); d[2].push(tgt); d[3].push(spd); d[4].push(trq);
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
        s.top.setData([x, pad(y(1)), pad(y(2))]);
        s.bottom.setData([x, pad(y(3)), pad(y(4))]);
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

  // -- console log ------------------------------------------------------------------
  function fmtTime(ns) { return (ns / 1e9).toFixed(6).padStart(11, " "); }

  function onLog(lines, dropped) {
    const log = $("log");
    const stick = log.scrollTop + log.clientHeight >= log.scrollHeight - 8;
    const frag = document.createDocumentFragment();
    if (dropped) frag.appendChild(logLine(state.lastTime, "!", "… " + dropped + " lines not shown (page too slow)", "note"));
    for (const [time, kind, text, motor, origin] of lines) {
      const sent = kind === ">";
      const line = kind === "note" ? logLine(time, "!", text, "note")
        : logLine(time, sent ? ">" : "<", text, sent ? "sent" : "k-" + kind);
      if (!sent && kind !== "note" && origin !== "web" && origin !== "motor") {
        const o = document.createElement("span");
        o.className = "origin";
        o.textContent = " (" + origin + ")";
        line.appendChild(o);
      }
      frag.appendChild(line);
    }
    log.appendChild(frag);
    while (log.childElementCount > MAX_LOG) log.removeChild(log.firstElementChild);
    if (stick) log.scrollTop = log.scrollHeight;
  }

  function logLine(time, dir, text, cls) {
    const div = document.createElement("div");
    div.className = "l " + cls;
    const t = document.createElement("span"); t.className = "t"; t.textContent = fmtTime(time);
    const d = document.createElement("span"); d.className = "d"; d.textContent = " " + dir + " ";
    const x = document.createElement("span"); x.className = "x"; x.textContent = text;
    div.append(t, d, x);
    return div;
  }

  function localNote(text) { onLog([], 0); $("log").appendChild(logLine(state.lastTime, "!", text, "note")); $("log").scrollTop = $("log").scrollHeight; }

  function note(id, text) { $(id).textContent = text || ""; }

  // -- console input -------------------------------------------------------------------
  function setupConsole() {
    try { state.history = JSON.parse(localStorage.getItem("coolmuscle-history") || "[]"); } catch (e) { state.history = []; }
    const input = $("cml-input");
    $("cml-form").addEventListener("submit", async (ev) => {
      ev.preventDefault();
      const line = input.value;
      if (!line.trim()) return;
      if (line.length > MAX_LINE) { note("cml-note", "line too long (the motor keeps " + MAX_LINE + " characters)"); return; }
      state.history = state.history.filter((h) => h !== line).concat([line]).slice(-200);
      localStorage.setItem("coolmuscle-history", JSON.stringify(state.history));
      state.historyAt = -1;
      input.value = "";
      note("cml-note", "");
      const r = await request("cml", { line, motor: Number($("cml-motor").value) });
      if (!r.ok) { note("cml-note", r.error); localNote(r.error); }
      else if (r.note) { note("cml-note", r.note); localNote(r.note); }
    });
    input.addEventListener("keydown", (ev) => {
      if (ev.key !== "ArrowUp" && ev.key !== "ArrowDown") return;
      ev.preventDefault();
      const h = state.history;
      if (!h.length) return;
      if (state.historyAt < 0) state.historyAt = h.length;
      state.historyAt += ev.key === "ArrowUp" ? -1 : 1;
      state.historyAt = Math.max(0, Math.min(h.length, state.historyAt));
      input.value = state.historyAt === h.length ? "" : h[state.historyAt];
    });
  }

  // -- banks ----------------------------------------------------------------------------
  function setupBanks() {
    const list = $("bank-list");
    list.addEventListener("change", () => {
      const bank = state.banks && state.banks.find((b) => b.label === list.value);
      if (bank) $("bank-text").value = [bank.label].concat(bank.lines, ["END"]).join("\n");
    });
    $("bank-refresh").addEventListener("click", listBanks);
    $("bank-upload").addEventListener("click", uploadBank);
    $("bank-start").addEventListener("click", () => {
      const head = bankHead();
      if (!head) { showDiag([{ text: "the text has no bank header (B#.n or L#.n)", error: true }]); return; }
      sendLine("[" + (head.ladder ? "L" : "") + head.number + "." + head.motor);
    });
    $("bank-stop").addEventListener("click", () => {
      const head = bankHead();
      sendLine(head && head.ladder ? "]L." + head.motor : "]");
    });
  }

  function bankHead() {
    const first = $("bank-text").value.split("\n").map((l) => l.trim()).find((l) => l);
    const m = /^([BL])(\d+)(?:\.(\d+))?$/i.exec(first || "");
    if (!m) return null;
    return { ladder: m[1].toUpperCase() === "L", number: Number(m[2]), motor: Number(m[3] || $("bank-motor").value) };
  }

  async function sendLine(line) {
    const r = await request("cml", { line, motor: Number($("bank-motor").value) });
    if (!r.ok) localNote(r.error);
  }

  async function listBanks() {
    const r = await request("banks", { motor: Number($("bank-motor").value) });
    if (!r.ok) { showDiag([{ text: r.error, error: true }]); return; }
    state.banks = r.banks.banks;
    const list = $("bank-list");
    list.textContent = "";
    list.add(new Option(state.banks.length ? "view a bank…" : "no banks", ""));
    for (const b of state.banks) list.add(new Option(b.label + " (" + b.lines.length + " lines)", b.label));
    showDiag([{ text: r.banks.summary || (state.banks.length + " banks") }]);
  }

  async function uploadBank() {
    const text = $("bank-text").value;
    if (text.length > MAX_BANK) { showDiag([{ text: "bank text too long (at most " + MAX_BANK + " characters)", error: true }]); return; }
    showDiag([{ text: "checking and uploading…" }]);
    const r = await request("bank_upload", { motor: Number($("bank-motor").value), text });
    if (!r.ok) { showDiag([{ text: r.error, error: true }]); return; }
    const items = r.diagnostics.map((d) => ({ text: "line " + d.line + ":" + d.column + " " + d.severity + ": " + d.message, error: d.severity === "error", line: d.line }));
    if (r.uploaded) {
      if (r.differences.length) r.differences.forEach((d) => items.push({ text: d, error: true }));
      else items.push({ text: "uploaded " + r.banks.join(", ") + "; read back identical", ok: true });
    } else items.push({ text: "not uploaded", error: true });
    showDiag(items);
  }

  function showDiag(items) {
    const ol = $("bank-result");
    ol.textContent = "";
    for (const it of items) {
      const li = document.createElement("li");
      li.className = it.error ? "error" : it.ok ? "ok" : "";
      if (it.line) {
        const b = document.createElement("button");
        b.type = "button"; b.className = "linkish"; b.textContent = it.text;
        b.setAttribute("aria-label", "Go to line " + it.line + ": " + it.text);
        b.addEventListener("click", () => selectLine($("bank-text"), it.line));
        li.appendChild(b);
      } else li.textContent = it.text;
      ol.appendChild(li);
    }
  }

  function selectLine(area, n) {
    const lines = area.value.split("\n");
    const start = lines.slice(0, n - 1).reduce((a, l) => a + l.length + 1, 0);
    area.focus();
    area.setSelectionRange(start, start + (lines[n - 1] || "").length);
  }

  // -- faults ----------------------------------------------------------------------------
  function buildFaults(faults) {
    const box = $("faults");
    for (const [name, params] of Object.entries(faults)) {
      const row = document.createElement("div");
      row.className = "fault";
      const btn = document.createElement("button");
      btn.type = "button";
      btn.textContent = name.replace(/_/g, " ");
      btn.dataset.testid = "fault-" + name;
      btn.setAttribute("aria-label", "Inject " + name.replace(/_/g, " "));
      row.appendChild(btn);
      const inputs = {};
      for (const [key, value] of Object.entries(params)) {
        const label = document.createElement("label");
        label.textContent = key + " ";
        let el;
        if (typeof value === "boolean") { el = document.createElement("input"); el.type = "checkbox"; el.checked = value; }
        else if (key === "cable") { el = document.createElement("select"); ["io", "power"].forEach((c) => el.add(new Option(c, c))); }
        else { el = document.createElement("input"); el.type = "number"; el.value = value; el.step = "any"; el.className = "num"; }
        el.dataset.testid = "fault-" + name + "-" + key;
        el.setAttribute("aria-label", key + " of " + name.replace(/_/g, " "));
        label.appendChild(el);
        row.appendChild(label);
        inputs[key] = el;
      }
      btn.addEventListener("click", async () => {
        const p = {};
        for (const [key, el] of Object.entries(inputs)) {
          if (el.type === "checkbox") p[key] = el.checked;
          else if (el.tagName === "SELECT") p[key] = el.value;
          else {
            const v = Number(el.value);
            if (el.value.trim() === "" || !Number.isFinite(v)) { note("fault-note", key + " must be a number"); return; }
            p[key] = v;
          }
        }
        const motor = Number($("fault-motor").value);
        const r = await request("fault", { motor, fault: name, params: p });
        note("fault-note", r.ok ? name.replace(/_/g, " ") + " injected on ID" + motor : r.error);
      });
      box.appendChild(row);
    }
  }

  // -- downloads ---------------------------------------------------------------------------
  function setDownloadLinks() {
    const q = state.token ? "?token=" + encodeURIComponent(state.token) : "";
    $("dl-csv").href = "/api/trace.csv" + q;
    $("dl-parquet").href = "/api/trace.parquet" + q;
    $("dl-png").href = "/api/plot.png" + q;
  }

  $("record").addEventListener("click", async () => {
    const r = await request("record", {});
    if (r.ok) showRecording(true); else $("record-state").textContent = r.error;
  });

  // -- start ------------------------------------------------------------------------------
  setupConsole();
  setupBanks();
  $("window").addEventListener("change", () => { state.dirty = true; });
  $("xy-x").addEventListener("change", () => { state.dirty = true; });
  $("xy-y").addEventListener("change", () => { state.dirty = true; });
  let resizeTimer = null;
  window.addEventListener("resize", () => { clearTimeout(resizeTimer); resizeTimer = setTimeout(resizeCharts, 150); });
  requestAnimationFrame(redraw);
  boot();
})();
