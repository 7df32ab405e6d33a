/* coolmuscle dashboard: the wire-fault panel (docs/wire-faults.md).
 *
 * Built from the vocabulary the server sends in "hello" (msg.wire: every door, its
 * fault kinds and their parameters, the same registry machine files are checked
 * against).  A fault is installed with "wire_fault", ended with "wire_clear"; each
 * answer carries the faults installed now, listed under the controls.  What a fault
 * does arrives in the log as an event of kind "wire".
 */
"use strict";

window.Coolmuscle = window.Coolmuscle || {};

window.Coolmuscle.wirePanel = function ({ $, request, note }) {
  const SCHEDULE_HELP = {
    at: "starts this many seconds from now", until: "ends this many seconds from now",
    every: "hits one message in N", probability: "hits a message with this probability",
    seed: "the fault's own generator", count: "at most this many hits",
    motor: "the motor (chain faults)",
  };
  let vocab = null;

  function kindsOf(door) { return (vocab.doors[door] || { kinds: [] }).kinds; }
  function currentKind() {
    return kindsOf($("wire-door").value).find((k) => k.kind === $("wire-kind").value);
  }

  function input(testid, label, param) {
    const wrap = document.createElement("label");
    wrap.textContent = label + " ";
    let el;
    if (param && param.type === "bool") {
      el = document.createElement("input"); el.type = "checkbox"; el.checked = !!param.default;
    } else if (param && param.choices) {
      el = document.createElement("select");
      for (const c of param.choices) el.add(new Option(c, c));
      if (param.default != null) el.value = param.default;
    } else {
      el = document.createElement("input"); el.type = "number"; el.step = "any";
      el.className = "num";
      if (param && param.default != null) el.value = param.default;
      if (param && param.min != null) el.min = param.min;
      if (param && param.max != null) el.max = param.max;
    }
    el.dataset.testid = testid;
    el.setAttribute("aria-label", label + (param && param.doc ? ": " + param.doc : ""));
    if (param && param.doc) el.title = param.doc;
    wrap.appendChild(el);
    return { wrap, el };
  }

  function value(el) {
    if (el.type === "checkbox") return el.checked;
    if (el.tagName === "SELECT") return el.value;
    if (el.value.trim() === "") return null;
    const v = Number(el.value);
    return Number.isFinite(v) ? v : NaN;
  }

  function showKind() {
    const kind = currentKind();
    const box = $("wire-params");
    box.textContent = "";
    if (!kind) return;
    $("wire-doc").textContent = kind.doc + (kind.seen ? " (" + kind.seen + ")" : "");
    for (const p of kind.params) {
      box.appendChild(input("wire-param-" + p.name, p.name.replace(/_/g, " "), p).wrap);
    }
    for (const key of ["every", "probability", "count"]) $("wire-" + key).disabled = kind.lasting;
    $("wire-motor").disabled = kind.motor === "none";
  }

  function showKinds() {
    const sel = $("wire-kind");
    sel.textContent = "";
    for (const k of kindsOf($("wire-door").value)) sel.add(new Option(k.kind.replace(/_/g, " "), k.kind));
    showKind();
  }

  function showFaults(faults) {
    const list = $("wire-list");
    list.textContent = "";
    for (const f of faults || []) {
      const li = document.createElement("li");
      const params = Object.entries(f.params || {}).map(([k, v]) => k + "=" + v).join(" ");
      li.textContent = "#" + f.id + " " + f.door + " " + f.kind.replace(/_/g, " ") +
        (f.motor ? " ID" + f.motor : "") + (params ? " " + params : "") +
        (f.live ? " · live" : " · from " + f.at + " s") + " · " + f.hits + " hit(s) ";
      li.dataset.testid = "wire-fault-" + f.id;
      const end = document.createElement("button");
      end.type = "button";
      end.textContent = "end";
      end.dataset.testid = "wire-end-" + f.id;
      end.setAttribute("aria-label", "End wire fault " + f.id);
      end.addEventListener("click", async () => {
        const r = await request("wire_clear", { fault: f.id });
        if (r.ok) showFaults(r.faults); else note("wire-note", r.error);
      });
      li.appendChild(end);
      list.appendChild(li);
    }
  }

  async function inject() {
    const kind = currentKind();
    if (!kind) return;
    const schedule = {}, params = {};
    for (const key of vocab.schedule) {
      const el = $("wire-" + key);
      if (el.disabled) continue;
      const v = value(el);
      if (Number.isNaN(v)) { note("wire-note", key + " must be a number"); return; }
      if (v !== null) schedule[key] = v;
    }
    for (const p of kind.params) {
      const v = value($("wire-params").querySelector('[data-testid="wire-param-' + p.name + '"]'));
      if (Number.isNaN(v)) { note("wire-note", p.name + " must be a number"); return; }
      if (v !== null) params[p.name] = v;
    }
    const r = await request("wire_fault", { door: $("wire-door").value, kind: kind.kind, schedule, params });
    note("wire-note", r.ok ? "wire fault " + r.fault + " installed: " + kind.door + " " +
         kind.kind.replace(/_/g, " ") : r.error);
    if (r.ok) showFaults(r.faults);
  }

  function build(wire) {
    vocab = wire;
    const doors = $("wire-door");
    for (const d of Object.keys(vocab.doors)) doors.add(new Option(d, d));
    doors.addEventListener("change", showKinds);
    $("wire-kind").addEventListener("change", showKind);
    const sched = $("wire-schedule");
    for (const key of vocab.schedule) {
      const { wrap, el } = input("wire-" + key, key, { doc: SCHEDULE_HELP[key] || "" });
      el.id = "wire-" + key;
      sched.appendChild(wrap);
    }
    $("wire-inject").addEventListener("click", inject);
    $("wire-clear").addEventListener("click", async () => {
      const r = await request("wire_clear", {});
      note("wire-note", r.ok ? r.cleared + " wire fault(s) ended" : r.error);
      if (r.ok) showFaults(r.faults);
    });
    showKinds();
    request("wire_faults", {}).then((r) => { if (r.ok) showFaults(r.faults); });
  }

  return { build };
};
