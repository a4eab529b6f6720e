// The fmscell cell dashboard: machines (polled at 5 Hz), library, jobs, dispatches, events
// (server-sent), fault injection when the cell enables it. Plain ES modules, no build step.

import { ApiError, api, auth, eventsUrl, items, newKey } from "./api.js";
import { ToolpathPlot, planeOf } from "./plot.js";
import { busLoad, machineState, statusView, tipAxes } from "./status.js";

const MACHINE_POLL_MS = 200; // 5 Hz: smooth enough for the toolpath plot
const LIST_REFRESH_MS = 10000; // safety net when the event stream is down
const $ = (sel, root = document) => root.querySelector(sel);

const state = {
  machines: new Map(), // name -> {el, plot, kind, plane}
  machineNames: [],
  machineKinds: {}, // name -> kind (the program view picks a machine the source is meant for)
  programs: [],
  programsSignature: "",
  faultTypes: null, // null: fault injection not offered by this cell
  role: null, // the key's role (GET /api/whoami)
  lastEventId: 0,
  events: null,
};

// ------------------------------------------------------------------------------ helpers

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k === "class") e.className = v;
    else if (k === "text") e.textContent = v;
    else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v === true ? "" : String(v));
  }
  for (const c of children) if (c !== null && c !== undefined) e.append(c);
  return e;
}

function fmt(n, digits = 3) {
  if (n === null || n === undefined || n === "") return "—"; // UNAVAILABLE, not zero
  const v = Number(n);
  return Number.isFinite(v) ? v.toFixed(digits) : "—";
}

function when(iso) {
  if (!iso) return "—";
  const d = new Date(iso);
  return Number.isNaN(d.getTime()) ? String(iso) : d.toLocaleString();
}

let noticeTimer = null;
export function notify(message, kind = "error") {
  const n = $("#notice");
  n.textContent = message;
  n.dataset.kind = kind;
  n.hidden = false;
  clearTimeout(noticeTimer);
  noticeTimer = setTimeout(() => (n.hidden = true), 10000);
}

function explain(err, what) {
  if (err instanceof ApiError) {
    const p = err.problem;
    let msg = `${what}: ${p.detail || p.title || err.message}`;
    if (err.status === 403 && p.needed_role) msg += ` (needs the ${p.needed_role} role)`;
    if (Array.isArray(p.errors) && p.errors.length) {
      msg += " — " + p.errors.slice(0, 3).map((e) => e.message || e.detail || JSON.stringify(e)).join("; ");
    }
    return msg;
  }
  return `${what}: ${err?.message || err}`;
}

// `background`: a refresh the page runs by itself. Once the user chose to go on without a
// key, its 401 is expected and not news: notifying it on every poll would replace the "No API
// key" hint within a second. What the user does (release, dispatch, ...) still says why.
async function attempt(what, fn, { background = false } = {}) {
  try {
    return await fn();
  } catch (err) {
    const expected = background && auth.declined && err instanceof ApiError && err.status === 401;
    if (!expected) notify(explain(err, what));
    return undefined;
  }
}

// ------------------------------------------------------------------------------ API key

function keyDialog(reason) {
  const dlg = $("#key-dialog");
  $("#key-reason").textContent =
    `${reason} The key is kept in this browser only (localStorage).`;
  $("#key-input").value = "";
  return new Promise((resolve) => {
    const done = (key) => {
      dlg.removeEventListener("close", onClose);
      if (dlg.open) dlg.close();
      resolve(key);
    };
    const onClose = () => {
      if (dlg.returnValue === "save" && $("#key-input").value) {
        auth.key = $("#key-input").value.trim();
        auth.declined = false;
        refreshWhoami().then(loadFaultTypes);
        restartEvents();
        done(auth.key);
      } else {
        notify("No API key: the page shows what needs none. Use “API key…” to sign in.", "warning");
        done(null);
      }
    };
    dlg.returnValue = "";
    dlg.addEventListener("close", onClose);
    $("#key-cancel").onclick = () => dlg.close("");
    $("#key-forget").onclick = () => {
      auth.key = "";
      auth.declined = true; // do not ask again at once: the user just said no key
      $("#whoami").textContent = "not signed in";
      done(null);
    };
    if (!dlg.open) dlg.showModal();
    $("#key-input").focus();
  });
}

async function refreshWhoami() {
  try {
    const me = await api("/api/whoami");
    state.role = me.role;
    $("#whoami").textContent = `${me.user} (${me.role})`;
  } catch {
    $("#whoami").textContent = "not signed in";
  }
}

// ------------------------------------------------------------------------------ machines

function ensureTile(m) {
  let entry = state.machines.get(m.name);
  if (entry) return entry;
  const frag = $("#machine-template").content.cloneNode(true);
  const tile = frag.querySelector(".tile");
  tile.dataset.machine = m.name;
  tile.setAttribute("aria-label", `machine ${m.name}`);
  tile.id = `machine-${m.name.replace(/[^A-Za-z0-9_-]/g, "_")}`;
  $(".m-name", tile).textContent = m.name;
  $(".m-kind", tile).textContent = m.kind;
  const busId = `${tile.id}-bus`;
  $(".m-bus", tile).id = busId;
  $(".m-bus-label", tile).setAttribute("for", busId);
  for (const b of tile.querySelectorAll("[data-command]")) {
    b.setAttribute("aria-label", `${b.textContent} on ${m.name}`);
    b.addEventListener("click", () => sendCommand(m.name, b.dataset.command));
  }
  $(".fault-form", tile).addEventListener("submit", (ev) => {
    ev.preventDefault();
    injectFault(m.name, tile);
  });
  $(".m-faults", tile).addEventListener("toggle", () => {
    if ($(".m-faults", tile).open) loadFaults(m.name, tile);
  });
  $("#machine-tiles").append(tile);
  entry = { el: tile, plot: null, kind: m.kind, plane: null };
  state.machines.set(m.name, entry);
  fillFaultTypes(tile);
  return entry;
}

function renderMachine(m) {
  const entry = ensureTile(m);
  const t = entry.el;
  const s = statusView(m.status);
  const [cls, label] = machineState(s);
  t.dataset.state = cls;
  $(".m-state", t).textContent = label;
  $(".m-mode", t).textContent = s ? `${s.controller_mode ?? "—"} / ${s.mode_detail ?? "—"}` : "—";
  $(".m-exec", t).textContent = s?.execution ?? "—";
  $(".m-program", t).textContent = s?.program || "—";
  $(".m-line", t).textContent = s && s.line ? String(s.line) : "—";
  $(".m-block", t).textContent = s?.block || "";
  $(".m-feed", t).textContent = s
    ? `${fmt(s.path_feed_rate, 0)} mm/min · ${fmt(s.feed_override, 0)} % (rapid ${fmt(s.rapid_override, 0)} %)`
    : "—";
  $(".m-spindle", t).textContent = s
    ? `${fmt(s.spindle_speed, 0)} rpm · ${fmt(s.spindle_override, 0)} % · load ${fmt(s.spindle_load, 0)} %`
    : "—";
  $(".m-parts", t).textContent = s ? String(s.part_count ?? "—") : "—";
  $(".m-scan", t).textContent = s && s.plc_scan_time_ms != null ? `${fmt(s.plc_scan_time_ms, 3)} ms` : "—";

  const axes = s?.axes || {};
  const names = Object.keys(axes);
  const body = $(".m-axes", t);
  body.replaceChildren(
    ...names.map((a) => {
      const x = axes[a] || {};
      return el(
        "tr",
        { "data-axis": a },
        el("th", { scope: "row", text: a }),
        el("td", { class: "num", text: fmt(x.actual) }),
        el("td", { class: "num", text: fmt(x.commanded) }),
        el("td", { class: "num", text: x.commanded == null || x.actual == null ? "—" : fmt(x.commanded - x.actual) }),
      );
    }),
  );
  if (!entry.plot && names.length >= 2) {
    entry.plane = planeOf(m.kind, names);
    entry.plot = new ToolpathPlot($(".m-plot", t), entry.plane);
    $(".m-plane", t).textContent = `plane ${entry.plane.join("–")}`;
  }
  if (entry.plot && s?.program !== entry.program) {
    entry.plot.clear(); // a new program draws a new toolpath
    entry.program = s?.program;
  }
  if (entry.plot) {
    // a 5-axis table-table machine (mill5) plots the tool tip by forward kinematics (the
    // path on the part), not its raw axes
    const tip = tipAxes(s?.tool_tip);
    const shown = tip || axes;
    entry.plot.push(shown);
    entry.plot.draw();
    const [h, v] = entry.plane;
    const what = tip ? "tool tip (forward kinematics)" : "actual";
    $(".m-plot", t).setAttribute(
      "aria-label",
      `Toolpath of ${m.name}, ${h}${v} plane: ${what} ${h} ${fmt(shown[h]?.actual)}, ${v} ${fmt(shown[v]?.actual)} mm`,
    );
    $(".m-plane", t).textContent = tip
      ? `plane ${entry.plane.join("–")} · tool tip, deviation ${fmt(s.tool_tip.deviation, 4)} mm (peak ${fmt(s.tool_tip.peak, 4)})`
      : `plane ${entry.plane.join("–")}`;
  }

  const bl = busLoad(s);
  $(".m-bus", t).value = bl ? Math.min(100, bl.mean) : 0;
  $(".m-bus-text", t).textContent = bl ? `${fmt(bl.mean, 1)} % (peak ${fmt(bl.peak, 1)} %)` : "—";

  const alarms = s?.alarms || [];
  const notes = [];
  if ((s?.unreferenced || []).length) {
    notes.push(el("li", { class: "warning" }, `axis ${s.unreferenced.join(", ")} not referenced: home the machine`));
  }
  if (s?.cycle_start_refused) {
    notes.push(el("li", { class: "warning" }, `${s.cycle_start_refused}`));
  }
  $(".m-alarms", t).replaceChildren(
    ...alarms.map((a) =>
      el("li", { class: (a.severity || "FAULT").toLowerCase() },
        `${a.source || "NC"} ${a.number ?? ""}${a.axis ? ` [${a.axis}]` : ""}: ${a.text ?? ""}`),
    ),
    ...notes,
  );
  $(".m-faults", t).hidden = !faultPanelShown();
}

async function pollMachines() {
  try {
    const list = await api("/api/machines");
    const machines = items(list);
    state.machineNames = machines.map((m) => m.name);
    state.machineKinds = Object.fromEntries(machines.map((m) => [m.name, m.kind]));
    $("#machines-empty").hidden = machines.length > 0;
    for (const m of machines) renderMachine(m);
    for (const [name, entry] of state.machines) {
      if (!state.machineNames.includes(name)) {
        entry.el.remove();
        state.machines.delete(name);
      }
    }
    fillMachineSelects();
    $("#health").dataset.ok = "true";
  } catch (err) {
    if (!(err instanceof ApiError)) {
      $("#health").textContent = "host unreachable";
      $("#health").dataset.ok = "false";
    }
  } finally {
    setTimeout(pollMachines, MACHINE_POLL_MS);
  }
}

async function sendCommand(machine, command) {
  const r = await attempt(`${command} on ${machine}`, () =>
    api(`/api/machines/${encodeURIComponent(machine)}/commands`, { method: "POST", json: { command } }),
  );
  if (r !== undefined) notify(`${command} sent to ${machine}`, "info");
}

// ------------------------------------------------------------------------------ faults

async function loadFaultTypes() {
  try {
    const r = await api("/api/fault-types");
    let types = Array.isArray(r) ? r : r?.items || r?.fault_types || r?.types || r;
    if (!Array.isArray(types)) types = Object.entries(types || {}).map(([type, v]) => ({ type, ...(v || {}) }));
    state.faultTypes = types.map((t) => (typeof t === "string" ? { type: t } : t));
  } catch (err) {
    // 404: the cell runs without fault injection; 403: this key is not an admin's.
    state.faultTypes = null;
    if (err instanceof ApiError && err.status === 403) {
      $("#health").title = "fault injection needs an admin key";
    }
  }
  for (const { el: tile } of state.machines.values()) fillFaultTypes(tile);
}

// Injecting needs an admin: other roles see no panel rather than a form that is refused.
const faultPanelShown = () => state.faultTypes !== null && state.role === "admin";

function fillFaultTypes(tile) {
  const panel = $(".m-faults", tile);
  panel.hidden = !faultPanelShown();
  if (state.faultTypes === null) return;
  const sel = $(".f-type", tile);
  const chosen = sel.value;
  sel.replaceChildren(
    ...state.faultTypes.map((t) =>
      el("option", { value: t.type ?? t.name, text: t.type ?? t.name, title: t.description || "" }),
    ),
  );
  if (chosen) sel.value = chosen;
  sel.onchange = () => prefillFault(tile);
  prefillFault(tile);
}

// A fault type names its target ("drive:<AXIS>", "bus:<AXIS>", "plc") and its parameters
// with defaults: offer them, with the machine's first axis, so one click injects something.
function prefillFault(tile) {
  const t = (state.faultTypes || []).find((f) => (f.type ?? f.name) === $(".f-type", tile).value);
  if (!t) return;
  const axis = $(".m-axes tr[data-axis]", tile)?.dataset.axis || "X";
  $(".f-target", tile).value = String(t.target || "").replace("<AXIS>", axis);
  const params = {};
  for (const p of t.params || []) if (p.default !== null && p.default !== undefined) params[p.name] = p.default;
  $(".f-params", tile).value = JSON.stringify(params);
  // Parameters without a default must be given: name them with their units.
  const names = (t.params || []).map((p) => `${p.name}${p.unit ? ` (${p.unit})` : ""}`);
  $(".f-params", tile).title = names.length ? `parameters: ${names.join(", ")}` : "no parameters";
  $(".f-params", tile).placeholder = names.length ? `{"${t.params[0].name}": …}` : "{}";
  $(".f-type", tile).title = t.description || "";
}

async function loadFaults(machine, tile) {
  const r = await attempt(`faults of ${machine}`, () =>
    api(`/api/machines/${encodeURIComponent(machine)}/faults`),
  );
  if (r === undefined) return;
  $(".f-active", tile).replaceChildren(
    ...items(r).map((f) =>
      el("li", {},
        `#${f.id} ${f.type} ${f.target ?? ""} ${f.state ?? f.status ?? ""} `,
        el("button", {
          type: "button",
          "aria-label": `Clear fault ${f.id} on ${machine}`,
          onclick: async () => {
            await attempt("clear fault", () =>
              api(`/api/machines/${encodeURIComponent(machine)}/faults/${f.id}`, { method: "DELETE" }),
            );
            loadFaults(machine, tile);
          },
        }, "Clear"),
      ),
    ),
  );
}

async function injectFault(machine, tile) {
  let params;
  try {
    params = JSON.parse($(".f-params", tile).value || "{}");
  } catch (err) {
    notify(`fault params: not JSON (${err.message})`);
    return;
  }
  const body = { type: $(".f-type", tile).value, params };
  const target = $(".f-target", tile).value.trim();
  if (target) body.target = target;
  const duration = $(".f-duration", tile).value;
  if (duration) body.duration = Number(duration);
  const r = await attempt(`inject fault on ${machine}`, () =>
    api(`/api/machines/${encodeURIComponent(machine)}/faults`, { method: "POST", json: body }),
  );
  if (r !== undefined) {
    notify(`fault ${body.type} injected on ${machine}`, "info");
    loadFaults(machine, tile);
  }
}

// ------------------------------------------------------------------------------ library

async function loadPrograms() {
  const q = $("#program-search").value.trim();
  const page = await attempt(
    "program list",
    () => api(`/api/programs?limit=200${q ? `&q=${encodeURIComponent(q)}` : ""}`),
    { background: true },
  );
  if (page === undefined) return;
  const programs = items(page);
  const signature = JSON.stringify(programs);
  if (signature === state.programsSignature) return; // keep an open form untouched
  state.programsSignature = signature;
  state.programs = programs;
  // A list refresh must not close the release/dispatch form the user is typing in.
  const body = $("#program-rows");
  const open = body.querySelector("tr.action-row");
  const focused = open?.contains(document.activeElement) ? document.activeElement : null;
  body.replaceChildren(...programs.map(programRow));
  const anchor = open && body.querySelector(`tr[data-program="${open.dataset.for}"]`);
  if (anchor) {
    anchor.after(open);
    focused?.focus();
  }
}

function programRow(p) {
  const o = `O${String(p.number).padStart(4, "0")}`;
  const actions = el("td", { class: "actions" });
  const draft = p.latest_revision_id && p.latest_revision_id !== p.released_revision_id;
  if (draft) {
    actions.append(
      el("button", {
        type: "button",
        "aria-label": `Release ${o} revision ${p.latest_revision_id}`,
        onclick: () => openRelease(p, o),
      }, "Release…"),
    );
  }
  if (p.released_revision_id) {
    actions.append(
      el("button", {
        type: "button",
        "aria-label": `Dispatch ${o} revision ${p.released_revision_id}`,
        onclick: () => openDispatch(p, o),
      }, "Dispatch…"),
    );
  }
  const shown = p.released_revision_id ?? p.latest_revision_id;
  if (shown) {
    actions.append(
      el("button", {
        type: "button",
        "aria-label": `View ${o} revision ${shown}`,
        onclick: () => openView(p, o, shown),
      }, "View…"),
    );
  }
  return el(
    "tr",
    { "data-program": p.id, "data-number": p.number },
    el("td", { class: "mono", text: o }),
    el("td", { text: p.name }),
    el("td", { text: p.machine_kind }),
    el("td", { class: "num", text: p.latest_revision_id ?? "—" }),
    el("td", { class: "num released", text: p.released_revision_id ?? "—" }),
    actions,
  );
}

function actionRow(p, form) {
  for (const r of document.querySelectorAll("#program-rows tr.action-row")) r.remove();
  const row = el("tr", { class: "action-row", "data-for": p.id }, el("td", { colspan: 6 }, form));
  const anchor = document.querySelector(`#program-rows tr[data-program="${p.id}"]`);
  anchor?.after(row);
  form.querySelector("input, select")?.focus();
}

function openRelease(p, o) {
  const form = el(
    "form",
    { class: "inline-form", "aria-label": `Release ${o}` },
    el("label", {}, `Approval comment for ${o} revision ${p.latest_revision_id} `,
      el("input", { type: "text", name: "comment", required: true, size: 30, value: "" })),
    el("button", { type: "submit" }, "Release"),
    el("button", { type: "button", onclick: () => form.closest("tr").remove() }, "Cancel"),
  );
  form.addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const comment = form.elements.comment.value.trim();
    const r = await attempt(`release of ${o}`, () =>
      api(`/api/revisions/${p.latest_revision_id}/release`, { method: "POST", json: { comment } }),
    );
    if (r !== undefined) {
      notify(`${o} revision ${p.latest_revision_id} released`, "info");
      form.closest("tr").remove();
      loadPrograms();
    }
  });
  actionRow(p, form);
}

function openDispatch(p, o) {
  const machines = el("select", { name: "machine", id: "dispatch-machine", required: true },
    ...state.machineNames.map((n) => el("option", { value: n, text: n })));
  const form = el(
    "form",
    { class: "inline-form", "aria-label": `Dispatch ${o}` },
    el("label", { for: "dispatch-machine" }, "Machine"),
    machines,
    el("label", { for: "dispatch-mode" }, "Mode"),
    el("select", { name: "mode", id: "dispatch-mode" },
      el("option", { value: "memory", text: "memory" }),
      el("option", { value: "drip_feed", text: "drip feed (BTR)" })),
    el("label", {}, el("input", { type: "checkbox", name: "start" }), " cycle start"),
    el("button", { type: "submit" }, "Dispatch"),
    el("button", { type: "button", onclick: () => form.closest("tr").remove() }, "Cancel"),
  );
  // One key per intended transfer: a retried click re-sends the same key, never a second copy.
  const key = newKey();
  form.addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const body = {
      revision_id: p.released_revision_id,
      machine: form.elements.machine.value,
      mode: form.elements.mode.value,
      start: form.elements.start.checked,
    };
    const r = await attempt(`dispatch of ${o}`, () =>
      api("/api/dispatches", { method: "POST", json: body, headers: { "Idempotency-Key": key } }),
    );
    if (r !== undefined) {
      notify(`${o} dispatched to ${body.machine} (#${r.id})`, "info");
      form.closest("tr").remove();
      loadDispatches();
    }
  });
  actionRow(p, form);
}

// The program view: the revision's text; an APT or CL revision beside the G-code it posts
// to for the machine chosen (GET /api/revisions/{id}/posted, a preview: nothing stored).
function openView(p, o, revId) {
  const source = el("pre", { class: "program-text", "aria-label": `${o} source text` });
  const posted = el("pre", { class: "program-text", "aria-label": `${o} posted text` });
  const note = el("p", { class: "post-note", role: "status" });
  const machines = el("select", { name: "machine", id: "view-machine" },
    ...state.machineNames.map((n) => el("option", { value: n, text: n })));
  const postedPane = el("figure", { class: "pane", hidden: true },
    el("figcaption", {}, el("label", { for: "view-machine" }, "Posted for "), machines), posted, note);
  const sourceCaption = el("figcaption", { text: `Revision ${revId}` });
  const form = el(
    "form",
    { class: "program-view", "aria-label": `Program ${o}` },
    el("div", { class: "side-by-side" }, el("figure", { class: "pane" }, sourceCaption, source),
      postedPane),
    el("button", { type: "button", onclick: () => form.closest("tr").remove() }, "Close"),
  );
  form.addEventListener("submit", (ev) => ev.preventDefault());
  async function post() {
    const machine = machines.value;
    posted.textContent = "";
    note.textContent = `posting for ${machine}…`;
    try {
      const r = await api(
        `/api/revisions/${revId}/posted?machine=${encodeURIComponent(machine)}`,
        { raw: true, headers: { Accept: "text/plain" } },
      );
      posted.textContent = await r.text();
      const tol = r.headers.get("X-Post-Tolerance-Mm");
      note.textContent = `${r.headers.get("X-Post-Processor")} for a ${r.headers.get("X-Machine-Kind")}` +
        (tol ? `, T = ${tol} mm` : "") + " (preview: dispatching stores it as a derived revision)";
    } catch (err) {
      const pr = err.problem || {};
      note.textContent = pr.line ? `line ${pr.line}: ${pr.reason || err.message}` : err.message;
    }
  }
  machines.addEventListener("change", post);
  actionRow(p, form);
  attempt(`revision ${revId} of ${o}`, async () => {
    const rev = await api(`/api/revisions/${revId}`);
    source.textContent = await api(`/api/revisions/${revId}/text`, { headers: { Accept: "text/plain" } });
    sourceCaption.textContent = `Revision ${revId} (${rev.kind})`;
    if (rev.kind === "apt" || rev.kind === "cl") {
      postedPane.hidden = false;
      const meant = state.machineNames.find((n) => rev.post_kinds.includes(state.machineKinds[n]));
      if (meant) machines.value = meant;
      await post();
    }
  });
}

async function upload(ev) {
  ev.preventDefault();
  const file = $("#upload-file").files[0];
  if (!file) return;
  const fd = new FormData();
  fd.append("file", file);
  const tags = $("#upload-tags").value.trim();
  if (tags) fd.append("tags", tags);
  fd.append("machine_kind", $("#upload-kind").value);
  const r = await attempt(`upload of ${file.name}`, () =>
    api("/api/programs", { method: "POST", body: fd }),
  );
  if (r === undefined) return;
  const rev = r.revision;
  if (rev && rev.check_ok === false) {
    const first = (rev.check_errors || [])[0];
    notify(
      `${file.name} stored as draft with ${rev.check_errors.length} check error(s)` +
        (first ? `: line ${first.line}: ${first.message}` : ""),
      "warning",
    );
  } else {
    notify(`${file.name} uploaded as O${r.program.number} revision ${rev?.id}`, "info");
  }
  $("#upload-form").reset();
  loadPrograms();
}

function fillMachineSelects() {
  for (const sel of document.querySelectorAll("#program-rows select[name=machine]")) {
    if (sel.options.length !== state.machineNames.length) {
      const v = sel.value;
      sel.replaceChildren(...state.machineNames.map((n) => el("option", { value: n, text: n })));
      sel.value = v;
    }
  }
}

// ------------------------------------------------------------------------------ jobs, dispatches

async function loadJobs() {
  const page = await attempt("job list", () => api("/api/jobs?limit=200"), {
    background: true,
  });
  if (page === undefined) return;
  $("#job-rows").replaceChildren(
    ...items(page).map((j) =>
      el(
        "tr",
        { "data-job": j.id, "data-status": j.status },
        el("td", { class: "num", text: j.id }),
        el("td", { class: "num", text: j.revision_id }),
        el("td", { class: "num", text: `${j.done} / ${j.quantity}` }),
        el("td", {}, el("span", { class: `badge job-${j.status}`, text: j.status })),
        el("td", { text: when(j.due_at) }),
        el("td", {},
          ["queued", "running", "interrupted"].includes(j.status)
            ? el("button", {
                type: "button",
                "aria-label": `Cancel job ${j.id}`,
                onclick: async () => {
                  await attempt(`cancel job ${j.id}`, () => api(`/api/jobs/${j.id}/cancel`, { method: "POST" }));
                  loadJobs();
                },
              }, "Cancel")
            : null),
      ),
    ),
  );
}

async function createJob(ev) {
  ev.preventDefault();
  const body = {
    revision_id: Number($("#job-revision").value),
    quantity: Number($("#job-quantity").value),
    cycle_time_s: Number($("#job-cycle").value || 60),
  };
  const r = await attempt("new job", () => api("/api/jobs", { method: "POST", json: body }));
  if (r !== undefined) {
    notify(`job ${r.id} queued`, "info");
    loadJobs();
  }
}

async function loadDispatches() {
  const page = await attempt("dispatch history", () => api("/api/dispatches?limit=50"), {
    background: true,
  });
  if (page === undefined) return;
  $("#dispatch-rows").replaceChildren(
    ...items(page).map((d) =>
      el(
        "tr",
        { "data-dispatch": d.id, "data-state": d.state, title: d.error || "" },
        el("td", { class: "num", text: d.id }),
        el("td", { class: "num", text: d.revision_id }),
        el("td", { text: d.machine }),
        el("td", { text: d.mode }),
        el("td", {}, el("span", { class: `badge dispatch-${d.state}`, text: d.state })),
        el("td", { class: "num", text: d.bytes_sent }),
        el("td", { text: d.verified === null || d.verified === undefined ? "—" : d.verified ? "yes" : "NO" }),
        el("td", { text: when(d.updated_at || d.created_at) }),
      ),
    ),
  );
}

// ------------------------------------------------------------------------------ events

const pending = new Set();
let refreshTimer = null;

function scheduleRefresh(what) {
  pending.add(what);
  if (refreshTimer) return;
  refreshTimer = setTimeout(() => {
    refreshTimer = null;
    const todo = [...pending];
    pending.clear();
    if (todo.includes("programs")) loadPrograms();
    if (todo.includes("jobs")) loadJobs();
    if (todo.includes("dispatches")) loadDispatches();
  }, 250);
}

function onEvent(msg) {
  let e;
  try {
    e = JSON.parse(msg.data);
  } catch {
    return;
  }
  state.lastEventId = Number(msg.lastEventId || e.event_id || state.lastEventId);
  const log = $("#event-log");
  log.prepend(
    el("li", {},
      el("time", { datetime: e.at, text: e.at ? new Date(e.at).toLocaleTimeString() : "" }),
      " ",
      el("span", { class: "mono", text: e.action || e.topic }),
      ` ${e.entity ?? ""} ${e.id ?? ""} ${e.machine ?? ""}`),
  );
  while (log.children.length > 60) log.lastChild.remove();
  const entity = String(e.entity || e.topic || "");
  if (/program|revision/.test(entity)) scheduleRefresh("programs");
  if (/job|allocation|decision/.test(entity)) scheduleRefresh("jobs");
  if (/dispatch/.test(entity)) {
    scheduleRefresh("dispatches");
    scheduleRefresh("jobs");
  }
}

function restartEvents() {
  if (state.events) state.events.close();
  const es = new EventSource(eventsUrl(state.lastEventId));
  state.events = es;
  es.onopen = () => {
    $("#live").textContent = "events: live";
    $("#live").dataset.ok = "true";
  };
  es.onmessage = onEvent;
  es.onerror = () => {
    $("#live").textContent = "events: reconnecting";
    $("#live").dataset.ok = "false";
    if (es.readyState === EventSource.CLOSED) {
      // Refused (401) or the host went away: try again later from the last event seen.
      setTimeout(() => state.events === es && restartEvents(), 5000);
    }
  };
}

// ------------------------------------------------------------------------------ start

async function health() {
  try {
    const r = await fetch("/api/health", { headers: { Accept: "application/json" } });
    const h = await r.json();
    $("#health").textContent = r.ok ? `host ok${h.insecure_open ? " (insecure-open)" : ""}` : "database unavailable";
    $("#health").dataset.ok = String(r.ok);
  } catch {
    $("#health").textContent = "host unreachable";
    $("#health").dataset.ok = "false";
  }
}

function start() {
  auth.onUnauthenticated = keyDialog;
  $("#key-button").addEventListener("click", () => keyDialog("Enter an API key."));
  $("#upload-form").addEventListener("submit", upload);
  $("#job-form").addEventListener("submit", createJob);
  let searchTimer = null;
  $("#program-search").addEventListener("input", () => {
    clearTimeout(searchTimer);
    searchTimer = setTimeout(loadPrograms, 250);
  });
  health();
  refreshWhoami().then(() => {
    loadFaultTypes();
    loadPrograms();
    loadJobs();
    loadDispatches();
    restartEvents();
    pollMachines();
  });
  setInterval(() => {
    health();
    loadPrograms();
    loadJobs();
    loadDispatches();
  }, LIST_REFRESH_MS);
  document.body.dataset.ready = "true";
}

start();
