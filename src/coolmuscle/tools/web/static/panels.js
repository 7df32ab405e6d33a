/* coolmuscle dashboard: the bank editor (check, upload, read back, start, stop) and
 * the fault buttons (docs/machine-file.md "Faults").  Requests go through the page's
 * one WebSocket (``request``); results are shown beside the controls.
 */
"use strict";

window.Coolmuscle = window.Coolmuscle || {};

window.Coolmuscle.panels = function ({ state, $, request, note, localNote }) {
  const MAX_BANK = 48 * 1024;      // characters; the server takes 48 Ki (actions.MAX_BANK_TEXT)
  const MAX_MESSAGE = 256 * 1024;  // bytes of one WebSocket message (server.MAX_MESSAGE)
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
      if (!head) { showDiag([], { text: "the text has no bank header (B#.n or L#.n)", error: true }); return; }
      sendLine("[" + (head.ladder ? "L" : "") + head.number + "." + head.motor);
    });
    $("bank-stop").addEventListener("click", () => {
      const head = bankHead();
      sendLine(head && head.ladder ? "]L." + head.motor : "]");
    });
  }

  function bankHead() {
    // the first B#.n / L#.n line (data lines may come before the bank, as in 2.2)
    for (const raw of $("bank-text").value.split("\n")) {
      const m = /^([BL])(\d+)(?:\.(\d+))?$/i.exec(raw.trim());
      if (m) return { ladder: m[1].toUpperCase() === "L", number: Number(m[2]), motor: Number(m[3] || $("bank-motor").value) };
    }
    return null;
  }

  async function sendLine(line) {
    const r = await request("cml", { line, motor: Number($("bank-motor").value) });
    if (!r.ok) localNote(r.error);
  }

  async function listBanks() {
    const r = await request("banks", { motor: Number($("bank-motor").value) });
    if (!r.ok) { showDiag([], { text: r.error, error: true }); return; }
    state.banks = r.banks.banks;
    const list = $("bank-list");
    list.textContent = "";
    list.add(new Option(state.banks.length ? "view a bank…" : "no banks", ""));
    for (const b of state.banks) list.add(new Option(b.label + " (" + b.lines.length + " lines)", b.label));
    showDiag([], { text: r.banks.summary || (state.banks.length + " banks") });
  }

  async function uploadBank() {
    const text = $("bank-text").value;
    if (text.length > MAX_BANK) { showDiag([], { text: "bank text too long (at most " + MAX_BANK + " characters)", error: true }); return; }
    // the request as sent (JSON escapes control characters 6 bytes each) within the
    // simulator's message limit (server.MAX_MESSAGE, 256 KiB)
    if (new TextEncoder().encode(JSON.stringify({ text })).length > MAX_MESSAGE - 1024) {
      showDiag([], { text: "bank text too large to send (control characters count six bytes each)", error: true }); return;
    }
    showDiag([], { text: "checking and uploading…" });
    const r = await request("bank_upload", { motor: Number($("bank-motor").value), text });
    if (!r.ok) { showDiag([], { text: r.error, error: true }); return; }
    // the findings are numbered (the checker's, then the read-back differences); the
    // outcome is said once below them, not counted as one of them
    const items = r.diagnostics.map((d) => ({ text: "line " + d.line + ":" + d.column + " " + d.severity + ": " + d.message, error: d.severity === "error", line: d.line }));
    let verdict;
    if (r.uploaded) {
      r.differences.forEach((d) => items.push({ text: d, error: true }));
      verdict = r.differences.length
        ? { text: "uploaded " + r.banks.join(", ") + "; read back different", error: true }
        : { text: "uploaded " + r.banks.join(", ") + "; read back identical", ok: true };
    } else verdict = { text: "not uploaded", error: true };
    showDiag(items, verdict);
  }

  function showDiag(items, verdict) {
    const said = $("bank-verdict");
    said.textContent = verdict.text;
    said.className = "diag verdict" + (verdict.error ? " error" : verdict.ok ? " ok" : "");
    const ol = $("bank-findings");
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


  return { setupBanks, buildFaults };
};
