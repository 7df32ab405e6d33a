/* coolmuscle dashboard: the desk (coolmuscle.tools.web.deskpage).
 *
 * The line badge (virtual, or the real motor and its line), the buttons of each motor
 * card (jog, enable "(", free ")", stop "]", alarm reset), the K-parameter editor
 * (table 6.1 beside the motor's ?90), scan, backup (the file is downloaded) and
 * restore (a file read in the browser, the report shown), and the twin's panel (its
 * differences beyond the compare tolerances, Save capture).  The same requests on
 * the virtual page and on a real motor's.
 */
"use strict";

window.Coolmuscle = window.Coolmuscle || {};

window.Coolmuscle.desk = function ({ state, $, request, note, localNote }) {
  const LONG_MS = 180000;          // scan, backup, restore: seconds on a slow line
  const MAX_BACKUP = 200 * 1024;   // characters (deskpage.MAX_BACKUP_TEXT)

  // -- the line ------------------------------------------------------------------------
  function hello(msg) {
    const line = msg.line || { kind: "virtual", text: "virtual" };
    state.line = line;
    const badge = $("line-badge");
    badge.textContent = line.text;
    badge.className = "badge " + (line.kind === "real" ? "real" : "virtual");
    badge.title = line.kind === "real" ? (line.poll ? "poll: " + line.poll : "") :
      "a virtual motor (coolmuscle sim)";
    const real = line.kind === "real";
    document.body.classList.toggle("real", real);
    $("vtime-label").textContent = real ? "time" : "virtual time";
    $("faults-panel").hidden = real;
    $("wire-panel").hidden = real;
    $("trace-panel").hidden = real;
    // a real motor's inputs and analog input are wired: shown, not driven
    for (const el of document.querySelectorAll(".inputs .toggle, .a-range")) el.disabled = real;
    showSilent(line.silent);
    const twin = line.twin;
    $("twin-panel").hidden = !twin;
    if (twin) showTwin(twin);
    const sel = $("k-motor");
    const was = sel.value;
    sel.textContent = "";
    for (const id of msg.motors) sel.add(new Option("ID" + id, String(id)));
    if (msg.motors.map(String).includes(was)) sel.value = was;
    if (!state.kRows) {
      const body = $("k-table").tBodies[0];
      body.textContent = "";
      const tr = body.insertRow();
      const td = tr.insertCell();
      td.colSpan = 6;
      td.className = "muted";
      td.textContent = "Read lists the motor's K parameters (?90.n) beside what each means, " +
        "its range and its factory value (table 6.1).";
    }
  }

  function showSilent(text) {
    $("line-state").textContent = text || "";
  }

  function onMessage(kind, text) {
    // the line's own state changes come as log messages; the badge area repeats them
    if (state.line && state.line.kind === "real" && kind === "message") {
      if (/^no answer from the motors|^the line failed/.test(text)) showSilent(text);
      else if (/^the motors answer again/.test(text)) showSilent("");
    }
  }

  // -- motor cards --------------------------------------------------------------------
  function cardButtons(node, id) {
    const ref = (cls, testid, label) => {
      const el = node.querySelector(cls);
      el.dataset.testid = testid + "-" + id;
      if (label) el.setAttribute("aria-label", label + " (ID" + id + ")");
      return el;
    };
    const step = ref(".b-step", "jog-step", "Jog step in pulses");
    const mnote = node.querySelector(".m-note");
    mnote.dataset.testid = "motion-note-" + id;
    const press = async (what, button) => {
      if (button.getAttribute("aria-busy") === "true") return;
      const body = { motor: id, what };
      if (what === "jog+" || what === "jog-") {
        const v = Number(step.value);
        if (!Number.isInteger(v) || v < 1) { mnote.textContent = "the jog step is a whole number of pulses, 1 or more"; return; }
        body.step = v;
      }
      button.setAttribute("aria-busy", "true");
      const r = await request("motion", body);
      button.removeAttribute("aria-busy");
      mnote.textContent = r.ok ? (r.sent + " → " + r.text + (r.note ? "; " + r.note : "")) : r.error;
      mnote.classList.toggle("ok", !!r.ok && !r.note);
    };
    const buttons = [[".b-jog-minus", "jog-minus", "Jog in the minus direction", "jog-"],
      [".b-jog-plus", "jog-plus", "Jog in the plus direction", "jog+"],
      [".b-enable", "enable", "Enable the motor", "enable"],
      [".b-free", "free", "Free the motor", "free"],
      [".b-stop", "stop", "Stop every motor and pause the bank", "stop"],
      [".b-reset", "alarm-reset", "Reset the alarm", "alarm_reset"]];
    for (const [cls, testid, label, what] of buttons) {
      const b = ref(cls, testid, label);
      b.addEventListener("click", () => press(what, b));
    }
  }

  // -- the K parameters ------------------------------------------------------------------
  async function readK() {
    const motor = Number($("k-motor").value || 1);
    note("k-note", "reading ?90." + motor + "…");
    const r = await request("k_table", { motor }, LONG_MS);
    if (!r.ok) { note("k-note", r.error); return; }
    note("k-note", "");
    state.kRows = r.rows;
    state.kMotor = motor;
    $("k-source").textContent = "ID" + motor + " " + r.firmware + " (" + r.source + ")";
    drawK();
  }

  function drawK() {
    const body = $("k-table").tBodies[0];
    body.textContent = "";
    const only = $("k-changed-only").checked;
    for (const row of state.kRows || []) {
      if (only && !row.changed) continue;
      body.appendChild(kRow(row));
    }
  }

  function kRow(row) {
    const tr = document.createElement("tr");
    tr.dataset.testid = "k-row-" + row.k;
    tr.classList.toggle("changed", row.changed);
    const td = (text, cls) => { const c = document.createElement("td"); c.textContent = text; if (cls) c.className = cls; tr.appendChild(c); return c; };
    td("K" + row.k, "k-num");
    const name = td(row.name + (row.unit && row.unit !== "-" ? " (" + row.unit + ")" : ""));
    const meaning = document.createElement("div");
    meaning.className = "k-meaning";
    meaning.textContent = row.meaning;
    name.appendChild(meaning);
    const cell = td("");
    const form = document.createElement("form");
    form.className = "k-edit";
    const input = document.createElement("input");
    input.type = "text";
    input.inputMode = "numeric";
    input.value = row.value === null ? "" : String(row.value);
    input.className = "num";
    input.dataset.testid = "k-value-" + row.k;
    input.setAttribute("aria-label", "K" + row.k + " " + row.name);
    const write = document.createElement("button");
    write.type = "submit";
    write.textContent = "Write";
    write.dataset.testid = "k-write-" + row.k;
    write.setAttribute("aria-label", "Write K" + row.k);
    if (row.line) { input.disabled = true; write.disabled = true; input.title = row.line; }
    const mark = document.createElement("span");
    mark.className = "k-mark";
    mark.dataset.testid = "k-changed-" + row.k;
    mark.textContent = row.changed ? "changed" : "";
    mark.title = row.changed ? "not the factory value" : "";
    form.append(input, write, mark);
    form.addEventListener("submit", (ev) => { ev.preventDefault(); writeK(row, input, mark, tr); });
    cell.appendChild(form);
    td(row.range);
    td(String(row.default));
    td(row.firmware.join(" "));
    return tr;
  }

  async function writeK(row, input, mark, tr) {
    const text = input.value.trim();
    if (!/^-?\d+$/.test(text)) { note("k-note", "K" + row.k + ": a whole number, please"); return; }
    const motor = state.kMotor;
    note("k-note", "writing K" + row.k + "." + motor + "=" + text + "…");
    const r = await request("k_write", { motor, k: row.k, value: Number(text) });
    if (!r.ok) {
      note("k-note", r.error);
      input.setAttribute("aria-invalid", "true");
      return;
    }
    input.removeAttribute("aria-invalid");
    row.value = r.value; row.changed = r.changed;
    input.value = String(r.value);
    mark.textContent = r.changed ? "changed" : "";
    tr.classList.toggle("changed", r.changed);
    note("k-note", "K" + row.k + "." + motor + "=" + r.value + " written and read back; Save $ keeps the data and banks through a power cycle");
  }

  async function saveK() {
    const motor = Number($("k-motor").value || 1);
    note("k-note", "saving ID" + motor + " ($." + motor + ")…");
    const r = await request("save", { motor }, LONG_MS);
    note("k-note", r.ok ? "saved." + motor : r.error);
  }

  // -- scan, backup, restore -----------------------------------------------------------
  function show(items) {
    const ol = $("desk-result");
    ol.textContent = "";
    for (const it of items) {
      const li = document.createElement("li");
      li.textContent = it.text;
      li.className = it.error ? "error" : it.ok ? "ok" : "";
      ol.appendChild(li);
    }
  }

  async function scan() {
    const baud = $("desk-baud").value;
    show([{ text: "scanning " + (baud ? "at " + baud + " bit/s" : "every K20 rate") + "…" }]);
    const r = await request("scan", baud ? { bauds: [Number(baud)] } : {}, LONG_MS);
    if (!r.ok) { show([{ text: r.error, error: true }]); return; }
    show(r.lines.map((text) => ({ text })).concat([{ text: r.summary, ok: true }]));
  }

  async function backup() {
    show([{ text: "reading every motor (about 2 s a motor at 38.4 kbps)…" }]);
    const r = await request("backup", {}, LONG_MS);
    if (!r.ok) { show([{ text: r.error, error: true }]); return; }
    const url = URL.createObjectURL(new Blob([r.text], { type: "text/plain" }));
    const a = document.createElement("a");
    a.href = url; a.download = r.name;
    document.body.appendChild(a); a.click(); a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 30000);
    show([{ text: "saved " + r.name + ": " + r.summary, ok: true }]);
  }

  async function restore() {
    const file = $("desk-file").files[0];
    if (!file) { show([{ text: "choose a backup file first (coolmuscle backup, or Backup here)", error: true }]); return; }
    if (file.size > MAX_BACKUP * 3) { show([{ text: file.name + " is too large for a backup", error: true }]); return; }
    const text = await file.text();
    if (text.length > MAX_BACKUP) { show([{ text: file.name + " is too large for a backup", error: true }]); return; }
    show([{ text: "restoring " + file.name + "…" }]);
    const r = await request("restore", { text, name: file.name, save: $("desk-save").checked }, LONG_MS);
    if (!r.ok) { show([{ text: r.error, error: true }]); return; }
    show(r.lines.map((text) => ({ text, error: /FAILED|not written/.test(text) }))
      .concat([{ text: r.restored ? (r.saved ? "restored and saved" : "restored (not saved: $ keeps data and banks)") : "the restore stopped", ok: r.restored, error: !r.restored }]));
    if (state.kRows) readK();
  }

  // -- the twin ---------------------------------------------------------------------------
  function showTwin(t) {
    $("twin-machine").textContent = "on " + t.machine;
    const text = t.differences
      ? t.differences + " difference" + (t.differences === 1 ? "" : "s") + " beyond the compare tolerances (" + t.compared + " lines compared)"
      : "agreeing: " + t.compared + " lines compared, none beyond the compare tolerances";
    const st = $("twin-state");
    st.textContent = text;
    st.classList.toggle("differs", !!t.differences);
    st.title = t.tolerance || "";
    const ol = $("twin-diffs");
    ol.textContent = "";
    for (const d of (t.recent || []).slice().reverse()) {
      const li = document.createElement("li");
      li.className = "error";
      li.textContent = d;
      ol.appendChild(li);
    }
  }

  async function saveCapture(ev) {
    ev.preventDefault();
    const q = state.token ? "?token=" + encodeURIComponent(state.token) : "";
    let r;
    try { r = await fetch("/api/capture.cml" + q, { cache: "no-store" }); } catch (e) { r = null; }
    if (!r || !r.ok) { note("twin-note", r ? "HTTP " + r.status : "not reachable"); return; }
    const url = URL.createObjectURL(await r.blob());
    const a = document.createElement("a");
    a.href = url; a.download = "coolmuscle-capture.cml";
    document.body.appendChild(a); a.click(); a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 30000);
    note("twin-note", "");
  }

  function setup() {
    $("k-read").addEventListener("click", readK);
    $("k-motor").addEventListener("change", readK);
    $("k-save").addEventListener("click", saveK);
    $("k-changed-only").addEventListener("change", drawK);
    $("desk-scan").addEventListener("click", scan);
    $("desk-backup").addEventListener("click", backup);
    $("desk-restore").addEventListener("click", restore);
    $("twin-capture").addEventListener("click", saveCapture);
  }

  return { setup, hello, cardButtons, showTwin, onMessage };
};
