/* coolmuscle dashboard: one page, one WebSocket, every motor of the chain.
 *
 * The server (coolmuscle.tools.web) sends "hello" (chain layout, recent log,
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
            state.token = null; askToken();
            note("cml-note", "the simulator refused the token: enter it again"); }
        }).catch(() => {});
      }
      if (!state.hello && ev.code === 1006) {
        // refused before opening: say why when the simulator has all the pages it takes
        fetch("/api/info").then((r) => r.json()).then((info) => {
          if (info.max_pages && info.pages >= info.max_pages && !state.ws) {
            setConn("the simulator has " + info.pages + " pages open, its most: close one" +
                    " (retrying)", false);
          }
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

  function request(kind, body, timeoutMs) {
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
      }, timeoutMs || REQUEST_TIMEOUT_MS);
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
    else if (msg.t === "twin") desk.showTwin(msg);
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
    const twin = msg.fields.includes("twin_position");
    const redo = state.twin !== twin;
    state.twin = twin;
    if (!same || redo || !state.cards.size) buildMotors(msg.motors);
    desk.hello(msg);
    if (!$("faults").childElementCount) buildFaults(msg.faults);
    if (msg.wire && !$("wire-door").options.length) wire.build(msg.wire);
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
    card.chartBox.setAttribute("role", "group");
    card.chartBox.setAttribute("aria-label", "Charts of ID" + id + ": position and target, speed and torque");
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
    desk.cardButtons(node, id);
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
      tpos: at("twin_position"), tspd: at("twin_speed"), ttrq: at("twin_torque"),
    };
    const shown = (v) => (v === null || v === undefined ? "—" : v);
    for (const row of msg.m) {
      const id = row[idx.id];
      const card = state.cards.get(id);
      if (!card) continue;
      card.position.textContent = shown(row[idx.position]);
      card.target.textContent = shown(row[idx.target]);
      card.speed.textContent = shown(row[idx.speed]);
      card.torque.textContent = shown(row[idx.torque]);
      card.temperature.textContent = shown(row[idx.temperature]);
      card.pe.textContent = shown(row[idx.pe]);
      card.voltage.textContent = row[idx.voltage] === null ? "—" : (row[idx.voltage] / 10).toFixed(1);
      card.aout.textContent = shown(row[idx.aout]);
      const ux = row[idx.status];
      card.status.textContent = ux === null ? "Ux not read yet" : statusText(ux);
      const alarm = UX_BITS.some(([bit, , isAlarm]) => isAlarm && (ux & bit));
      card.status.classList.toggle("alarm", alarm);
      card.node.classList.toggle("alarm", alarm);
      if (row[idx.inputs] !== null) showBits(card.inputs, row[idx.inputs], "Input", id);
      if (row[idx.outputs] !== null) showBits(card.outputs, row[idx.outputs], "Output", id);
      if (document.activeElement !== card.analog && row[idx.analog] !== null) {
        card.analog.value = row[idx.analog];
        card.analogValue.textContent = row[idx.analog];
      }
      const twin = idx.tpos >= 0 ? [row[idx.tpos], row[idx.tspd], row[idx.ttrq]] : null;
      pushSample(id, t, row[idx.position], row[idx.target], row[idx.speed], row[idx.torque], twin);
    }
    state.dirty = true;
  }

  function setTime(ns) {
    state.lastTime = ns;
    $("vtime").textContent = (ns / 1e9).toFixed(3);
  }

  const charts = window.Coolmuscle.charts(state, $);
  const { resetSeries, pushSample, redraw, resizeCharts } = charts;

  // -- console log ------------------------------------------------------------------
  function fmtTime(ns) { return (ns / 1e9).toFixed(6).padStart(11, " "); }

  function onLog(lines, dropped) {
    const log = $("log");
    const stick = log.scrollTop + log.clientHeight >= log.scrollHeight - 8;
    const frag = document.createDocumentFragment();
    if (dropped) frag.appendChild(logLine(state.lastTime, "!", "… " + dropped + " lines not shown (page too slow)", "k-note"));
    for (const [time, kind, text, motor, origin] of lines) {
      desk.onMessage(kind, text);
      const sent = kind === ">";
      const line = kind === "note" ? logLine(time, "!", text, "k-note")
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

  function localNote(text) { onLog([], 0); $("log").appendChild(logLine(state.lastTime, "!", text, "k-note")); $("log").scrollTop = $("log").scrollHeight; }

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
      else if (r.note) { note("cml-note", r.note); }   // the log has it from the simulator
      // the log itself is not read aloud (it can run at dozens of lines a second);
      // the replies to one's own line are
      note("cml-reply", r.ok && r.replies && r.replies.length ? r.replies.join(", ") : "");
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

  const { setupBanks, buildFaults } = window.Coolmuscle.panels(
    { state, $, request, note, localNote });
  const wire = window.Coolmuscle.wirePanel({ $, request, note });    // wire.js
  const desk = window.Coolmuscle.desk({ state, $, request, note, localNote });

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

  // a download that fails (nothing recorded, no pyarrow, busy) says why, beside the buttons
  for (const id of ["dl-csv", "dl-parquet", "dl-png"]) {
    $(id).addEventListener("click", async (ev) => {
      ev.preventDefault();
      const link = $(id);
      $("download-note").textContent = "preparing…";
      let r;
      try { r = await fetch(link.href, { cache: "no-store" }); } catch (e) { r = null; }
      if (!r || !r.ok) {
        let why = r ? "HTTP " + r.status : "simulator not reachable";
        try { why = (await r.json()).error || why; } catch (e) { /* not JSON */ }
        $("download-note").textContent = why;
        return;
      }
      const url = URL.createObjectURL(await r.blob());
      const save = document.createElement("a");
      save.href = url;
      save.download = "coolmuscle-" + link.getAttribute("href").split("/").pop().split("?")[0];
      document.body.appendChild(save);
      save.click();
      save.remove();
      setTimeout(() => URL.revokeObjectURL(url), 30000);
      $("download-note").textContent = "";
    });
  }

  // -- start ------------------------------------------------------------------------------
  setupConsole();
  setupBanks();
  desk.setup();
  $("window").addEventListener("change", () => { state.dirty = true; });
  $("xy-x").addEventListener("change", () => { state.dirty = true; });
  $("xy-y").addEventListener("change", () => { state.dirty = true; });
  let resizeTimer = null;
  window.addEventListener("resize", () => { clearTimeout(resizeTimer); resizeTimer = setTimeout(resizeCharts, 150); });
  requestAnimationFrame(redraw);
  boot();
})();
