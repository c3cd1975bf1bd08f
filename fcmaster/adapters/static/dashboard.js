// fcmaster dashboard: a live view of the fleet over /api/v1/stream, no build step.
//
// Rows are built once per drive and then updated in place: a message changes the text of
// the cells whose content changed, and never replaces a row, a button or an input. A
// button pressed for a human 150 ms keeps its click, and the Hz field keeps its text and
// its caret while the line is busy. Everything text-like goes in through textContent,
// never innerHTML: drive names and alarm texts come from the plant.
//
// Views: the fleet (#), one drive (#drive=NAME) and one line (#line=NAME), switched by the
// address's fragment; #token=… hands the page a token (taken out of the address at once).
"use strict";

const EVENTS_KEPT = 100;
const DRIVE_EVENTS_KEPT = 30;
const STALE_AFTER_S = 15;      // the daemon repeats a steady drive every 5 s
const OLD_FREQUENCY_S = 2;     // a frequency read this much before the status is marked
const WINDOW_S = 15 * 60;      // what the charts show

const fleet = { drives: new Map(), buses: new Map(), limits: {} };  // limits: configured Hz per drive
const rows = new Map();        // drive name -> its row and the text each cell shows
const cards = new Map();       // line name -> its card
const driveEvents = new Map(); // drive name -> recent event texts
let token = sessionStorage.getItem("fcmaster.token");
let role = null;
let socket = null;
let retryMs = 500;
let retryTimer = 0;
const dirty = new Set();
let linesDirty = false;
let frame = 0;
let view = { kind: "fleet" };
let detail = null;            // the open drive or line view: its charts and data

const $ = (id) => document.getElementById(id);

function el(tag, props = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(props)) {
    if (key === "class") node.className = value;
    else if (key === "text") node.textContent = value;
    else if (key.startsWith("data-")) node.setAttribute(key, value);
    else node[key] = value;
  }
  for (const child of children) if (child != null) node.append(child);
  return node;
}

// Set a node's text only when it differs, so the DOM is not touched for nothing.
function put(node, text) {
  if (node.textContent !== text) node.textContent = text;
}

function fmt(value, digits = 1) {
  if (value === null || value === undefined) return "–";
  if (typeof value !== "number") return String(value);
  return value.toFixed(digits);
}

function fmtValue(value) {
  if (typeof value !== "number") return fmt(value);
  if (Number.isInteger(value) && Math.abs(value) >= 1000) return String(value);
  const size = Math.abs(value);
  return value.toFixed(size >= 1000 ? 0 : size >= 100 ? 1 : 2);
}

const seconds = (rfc3339) => (rfc3339 ? Date.parse(rfc3339) / 1000 : null);
const clock = (s) => new Date(s * 1000).toLocaleTimeString();

// -- authentication -------------------------------------------------------------------

function takeTokenFromFragment() {
  const match = location.hash.match(/^#token=(.+)$/);
  if (!match) return false;
  token = decodeURIComponent(match[1]);
  sessionStorage.setItem("fcmaster.token", token);
  history.replaceState(null, "", location.pathname + location.search);
  return true;
}

async function api(path, options = {}) {
  const headers = { ...(options.headers || {}) };
  if (token) headers.Authorization = `Bearer ${token}`;
  if (options.body) headers["Content-Type"] = "application/json";
  return fetch(path, { ...options, headers });
}

async function identify() {
  const response = await api("/api/v1/whoami");
  if (response.status === 401) {
    setRole(null);
    $("identity").textContent = "not signed in";
    showNotice(token
      ? "The daemon does not accept this token: it is wrong or no longer configured. " +
        "Enter another with the Token… button."
      : "This dashboard needs a token: use the Token… button.");
    return token ? "wrong token" : "no token";
  }
  if (!response.ok) throw new Error(`whoami: HTTP ${response.status}`);
  const who = await response.json();
  setRole(who.role);
  $("identity").textContent = `${who.name} · ${who.role}`;
  hideNotice();
  return null;
}

function setRole(newRole) {
  if (newRole === role) return;
  role = newRole;
  document.body.classList.toggle("operator", role === "operator");
  for (const [name, record] of rows) fillCommands(record, fleet.drives.get(name));
}

function showNotice(text) { $("notice").textContent = text; $("notice").hidden = false; }
function hideNotice() { $("notice").hidden = true; }

// -- the stream -------------------------------------------------------------------------

function connect() {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  const query = token ? `?token=${encodeURIComponent(token)}` : "";
  const ws = new WebSocket(`${scheme}//${location.host}/api/v1/stream${query}`);
  socket = ws;
  ws.onopen = () => { retryMs = 500; setConnection("live", "pill-up"); };
  ws.onmessage = (event) => handle(JSON.parse(event.data));
  ws.onclose = (event) => {
    if (socket !== ws) return;  // replaced on purpose (a new token)
    socket = null;
    if (event.code === 1008) showNotice(`The stream was refused: ${event.reason || "not allowed"}.`);
    setConnection("reconnecting…", "pill-down");
    retry();
  };
}

function retry() {
  clearTimeout(retryTimer);
  retryTimer = setTimeout(start, retryMs);
  retryMs = Math.min(retryMs * 2, 10000);
}

function setConnection(text, cls) {
  const pill = $("connection");
  put(pill, text);
  pill.className = `pill ${cls}`;
}

function handle(message) {
  switch (message.type) {
    case "snapshot": {
      const names = new Set();
      for (const drive of message.drives) {
        fleet.drives.set(drive.name, drive);
        names.add(drive.name);
        dirty.add(drive.name);
      }
      for (const name of [...fleet.drives.keys()]) {
        if (!names.has(name)) { fleet.drives.delete(name); rows.get(name)?.row.remove(); rows.delete(name); }
      }
      fleet.buses.clear();
      for (const bus of message.buses) fleet.buses.set(bus.name, bus);
      fleet.limits = message.limits || {};
      linesDirty = true;
      loadJournal();
      break;
    }
    case "drive":
      fleet.drives.set(message.drive.name, message.drive);
      dirty.add(message.drive.name);
      if (detail && detail.kind === "drive" && detail.name === message.drive.name) sampleDrive(message.drive);
      break;
    case "line": {
      const bus = fleet.buses.get(message.bus) || { name: message.bus, drives: [] };
      bus.up = message.up;
      if (message.stats) bus.stats = message.stats;
      fleet.buses.set(message.bus, bus);
      linesDirty = true;
      if (message.reason) logEvent(`${message.bus}: ${message.up ? "up" : "down"} (${message.reason})`);
      if (message.stats && detail && detail.kind === "line" && detail.name === message.bus) sampleLine(bus);
      break;
    }
    case "condition":
    case "availability":
    case "command":
      logEvent(...eventText(message), message.drive);
      break;
    case "dropped":
      logEvent(`${message.count} events missed (this page fell behind)`, "warning");
      break;
  }
  schedule();
}

// A drive's event message as [text, class].
function eventText(message) {
  switch (message.type) {
    case "condition":
      return [`${message.drive}: ${message.kind} ${message.code} ${message.text} ` +
              (message.active ? "raised" : "cleared"), message.active ? message.kind : ""];
    case "availability":
      return [`${message.drive} went ${message.online ? "online" : "offline"}`, message.online ? "" : "warning"];
    case "command":
      return [`${message.drive}: ${message.command.action} by ${message.command.actor || "?"} → ` +
              `${message.result.outcome}${message.result.reason ? ` (${message.result.reason})` : ""}`, ""];
  }
  return [JSON.stringify(message), ""];
}

function schedule() {
  if (!frame) frame = requestAnimationFrame(render);
}

// -- the fleet table ----------------------------------------------------------------------

function render() {
  frame = 0;
  const body = $("drives").tBodies[0];
  for (const name of dirty) {
    const drive = fleet.drives.get(name);
    if (!drive) continue;
    let record = rows.get(name);
    if (!record) {
      record = makeRow(drive);
      rows.set(name, record);
      body.append(record.row);
    }
    updateRow(record, drive);
    if (detail && detail.kind === "drive" && detail.name === name) updateDriveView(drive);
  }
  dirty.clear();
  if (linesDirty) {
    renderLines();
    if (detail && detail.kind === "line") updateLineView();
    linesDirty = false;
  }
  put($("drive-count"), `(${fleet.drives.size})`);
}

function makeRow(d) {
  const record = { shown: {}, commandsFor: null };
  record.open = el("button", { type: "button", class: "link name", text: d.name,
                               "data-testid": "open", title: "open this drive's view",
                               onclick: () => { location.hash = `drive=${encodeURIComponent(d.name)}`; } });
  record.where = el("div", { class: "muted small" });
  record.watchdog = el("span", { class: "badge watchdog", "data-testid": "watchdog" });
  record.state = el("td", { class: "state", "data-testid": "state", "data-label": "State" });
  record.frequency = el("span");
  record.reference = el("div", { class: "muted small" });
  record.values = el("td", { class: "values", "data-testid": "values", "data-label": "Values" });
  record.conditions = el("ul", { class: "conditions", "data-testid": "conditions" });
  record.commands = el("td", { class: "operator-only", "data-label": "Commands" });
  record.row = el("tr", { "data-drive": d.name },
    el("td", { "data-label": "Drive" }, record.open, el("span", { class: "badge", text: d.control }), record.watchdog,
       record.where),
    record.state,
    el("td", { class: "frequency", "data-testid": "frequency", "data-label": "Output" },
       record.frequency, record.reference),
    record.values,
    el("td", { "data-label": "Alarms · warnings" }, record.conditions),
    record.commands);
  fillCommands(record, d);
  return record;
}

// Rebuild the pieces of a cell only when what they show changed.
function replaceIf(record, key, signature, node, build) {
  if (record.shown[key] === signature) return;
  record.shown[key] = signature;
  node.replaceChildren(...build());
}

function updateRow(record, d) {
  const row = record.row;
  row.classList.toggle("offline", !d.online);
  row.classList.toggle("faulted", d.fault);
  put(record.where, `${d.bus} · ${d.address}`);
  const [badge, verdictClass] = watchdogBadge(d);
  put(record.watchdog, badge);
  record.watchdog.hidden = !badge;
  record.watchdog.className = `badge watchdog ${verdictClass}`;
  record.watchdog.title = watchdogText(d);
  const pills = stateParts(d);
  replaceIf(record, "state", JSON.stringify(pills), record.state, () => pillNodes(pills));
  put(record.frequency, `${fmt(d.output_frequency_hz, 2)} Hz`);
  record.frequency.classList.toggle("old", frequencyIsOld(d));
  record.frequency.title = frequencyTitle(d);
  put(record.reference, d.reference_pct != null ? `ref ${fmt(d.reference_pct)} %` : "");
  const values = measured(d);
  replaceIf(record, "values", JSON.stringify(values), record.values, () => values.map(([param, label, text, title]) =>
    el("span", { class: "value", title: `${param} · ${title}` },
       el("span", { class: "vname", text: label }), " ", el("span", { text }))));
  const conditions = conditionItems(d);
  replaceIf(record, "conditions", JSON.stringify(conditions), record.conditions,
            () => conditions.map(([cls, text, title]) => el("li", { class: cls, text, title })));
  if (record.commandsFor !== commandsKey(d)) fillCommands(record, d);
  if (record.reset) record.reset.hidden = !hasSomethingToReset(d);  // only a trip needs one
  markStale(record, d);
}

function stateParts(d) {
  if (!d.online) return [["offline", "pill-down"]];
  const parts = [[d.running ? `running ${d.direction}` : "stopped", d.running ? "pill-up" : "pill-idle"]];
  if (d.fault) parts.push(["fault", "pill-down"]);
  if (d.warning) parts.push(["warning", "pill-warn"]);
  // Running at a reference of 0 the motor is powered but does not turn: "at reference" beside
  // 0.00 Hz would read as all well, so it says the speed instead.
  if (d.running && d.at_reference) parts.push(isStanding(d) ? ["at 0 Hz", "pill-warn"] : ["at reference", "pill-idle"]);
  return parts;
}

// The drive's own communication watchdog, as the audit judged it: what stops the motor if
// the gateway dies. A commanded drive that never answered has not been judged: nothing to
// read yet, which is not the same as a verdict.
const WATCHDOG_MEANING = {
  ok: "the drive stops by itself if the gateway dies",
  off: "the motor keeps running if the gateway dies",
  too_short: "normal polling or a gateway restart can trip the drive",
  unknown: "what the drive does cannot be told from its settings",
};
const VERDICT_WORDS = { ok: "OK", off: "Off", too_short: "Too short", unknown: "Cannot be judged" };
// Where each protocol keeps the watchdog's timeout (and FC its action), for the advice that
// fixes a verdict; the daemon's log has the same advice with a value for the line.
const WATCHDOG_PARAMETER = {
  "danfoss-fc": "8-03 Control Word Timeout Time",
  mitsubishi: "Pr.122 (PU connector) or Pr.336 (RS-485 terminals)",
  enc: "F2.16",
};
const WATCHDOG_SWITCH = { "danfoss-fc": "8-04 Control Word Timeout Function to [2] Stop or [5] Stop and trip, and " };

function watchdogAdvice(d) {
  const w = d.watchdog;
  if (!w || (w.verdict !== "too_short" && w.verdict !== "off")) return "";
  const where = WATCHDOG_PARAMETER[d.protocol] || "communication timeout";
  const how = "(fcmaster check prints the round; the daemon's log names a value), or give the drive " +
    "watchdog: {timeout_s: …} in the config, which fcmaster writes when it takes the drive over.";
  return w.verdict === "too_short"
    ? ` To clear it for good: set the drive's ${where} longer than the line's poll round ${how} ` +
      "Until then a Reset trips again."
    : ` To have it stop: set the drive's ${WATCHDOG_SWITCH[d.protocol] || ""}${where} to a few poll rounds ${how}`;
}

function watchdogText(d) {
  if (d.control !== "bus") return "monitor only: the gateway does not command this drive";
  const w = d.watchdog;
  if (!w) {
    return d.online ? "not judged yet: being read"
      : "not judged yet: the drive has not answered since the gateway started";
  }
  const timeout = w.timeout_s == null ? "no timeout" : `timeout ${w.timeout_s} s`;
  let text = `${VERDICT_WORDS[w.verdict] || w.verdict}: ${WATCHDOG_MEANING[w.verdict] || w.verdict} ` +
    `(${timeout}, action: ${w.action}).`;
  // what the gateway's start cost the drive: a timeout shorter than this trips it at a restart
  if (w.restart_gap_s != null && w.restart_gap_s >= 0.05) {
    text += ` Unfed for ${w.restart_gap_s.toFixed(1)} s when the gateway started.`;
  }
  return (d.online ? text : `${text} As read when the drive was last online.`) + watchdogAdvice(d);
}

function watchdogBadge(d) {
  if (d.control !== "bus") return ["", ""];
  const w = d.watchdog;
  if (!w) return ["watchdog –", ""];
  const cls = { ok: "badge-ok", off: "badge-bad", too_short: "badge-bad", unknown: "badge-warn" }[w.verdict] || "";
  return [`watchdog ${w.verdict.replaceAll("_", " ")}`, cls];
}

function pillNodes(parts) {
  return parts.map(([text, cls]) => el("span", { class: `pill ${cls}`, text }));
}

const isStanding = (d) => Math.abs(d.output_frequency_hz ?? 0) < 0.05;

function frequencyIsOld(d) {
  const read = seconds(d.output_frequency_updated_at), status = seconds(d.updated_at);
  return read != null && status != null && status - read > OLD_FREQUENCY_S;
}

function frequencyTitle(d) {
  const read = seconds(d.output_frequency_updated_at);
  return read == null ? "output frequency not read yet" : `output frequency read at ${clock(read)}`;
}

// Each protocol's tables keep the manual's own names ("Motor Current", "Power [kW]", "output
// current", "Output current"): the page shows them in one style, Title Case, with a
// bracketed unit dropped where the value shows the same unit after it ("Power 2.40 kW").
const SMALL_WORDS = new Set(["a", "an", "and", "as", "at", "by", "for", "in", "of", "on", "or", "per", "the", "to"]);

function valueLabel(name, unit) {
  const bare = name.replace(/\s*\[([^\]]+)\]$/, (whole, inside) =>
    (unit && inside.toLowerCase() === unit.toLowerCase() ? "" : whole));
  return bare.split(" ").map((word, i) => (i > 0 && SMALL_WORDS.has(word) ? word
    : word.replace(/(^|[(/])(\p{Ll})/gu, (_, before, letter) => before + letter.toUpperCase()))).join(" ");
}

// The drive's monitored values as [parameter, name, "8.82 A", title]; alarm and warning
// words are not values to read as numbers: their texts show under alarms and warnings.
function measured(d) {
  const out = [];
  for (const [param, v] of Object.entries(d.values || {})) {
    if (v.texts) continue;
    const read = seconds(v.updated_at);
    out.push([param, v.name ? valueLabel(v.name, v.unit) : param, `${fmtValue(v.value)}${v.unit ? ` ${v.unit}` : ""}`,
              read == null ? "" : `read at ${clock(read)}`]);
  }
  return out;
}

function conditionItems(d) {
  return [
    ...d.alarms.map((a) => ["alarm", `⚠ ${a.code} ${a.text}`, `alarm ${a.code}`]),
    ...d.warnings.map((w) => ["warning", `${w.code} ${w.text}`, `warning ${w.code}`]),
  ];
}

function markStale(record, d) {
  const age = Date.now() / 1000 - (seconds(d.updated_at) ?? 0);
  const stale = d.online && age > STALE_AFTER_S;
  record.row.classList.toggle("stale", stale);
  record.row.title = stale ? `no news from this drive for ${Math.round(age)} s` : "";
}

const commandsKey = (d) => `${role}|${d.control}`;

// The command cell is built once per role and never touched by state updates.
function fillCommands(record, d) {
  if (!d) return;
  record.commandsFor = commandsKey(d);
  if (role !== "operator") { record.commands.replaceChildren(); return; }
  if (d.control !== "bus") { record.commands.replaceChildren("monitor only"); return; }
  const name = d.name;
  const hz = el("input", { type: "text", inputMode: "decimal", placeholder: "Hz", autocomplete: "off",
                           "data-testid": "reference", title: "reference in Hz (Set), or the speed to Start at" });
  const button = (label, body, question, detail = () => "") => el("button", {
    type: "button", text: label, "data-action": body.action,
    onclick: () => confirmCommand(name, body, question, detail()),
  });
  const setReference = () => {
    const value = typedHz(hz.value);
    if (value === null) { toast("Enter a reference in Hz first (0 or more)", true); return; }
    confirmCommand(name, { action: "set_reference", frequency_hz: value },
                   `Set ${name}'s reference to ${value} Hz?`);
  };
  // A start says the speed it will run at: the one typed beside it, else the reference the
  // gateway commands now (which may be 0: powered, not turning).
  const start = () => {
    const drive = fleet.drives.get(name) || d;
    if (!hz.value.trim()) { confirmCommand(name, { action: "start" }, `Start ${name}?`, startDetail(drive)); return; }
    const value = typedHz(hz.value);
    if (value === null) { toast("Enter a speed in Hz (0 or more), or empty the field to keep the present reference", true); return; }
    confirmCommand(name, { action: "start", frequency_hz: value }, `Start ${name}?`,
                   `It will run at ${value} Hz, the speed typed beside the buttons.`);
  };
  hz.addEventListener("keydown", (event) => {
    if (event.key !== "Enter") return;
    event.preventDefault();  // this Enter must not go on to press a button in the dialog
    setReference();
  });
  const reset = button("Reset", { action: "reset" }, `Reset ${name}'s alarms?`, () => {
    const drive = fleet.drives.get(name) || d;
    return drive.watchdog?.verdict === "too_short"
      ? `Its watchdog is too short for this line: polling will trip it again.${watchdogAdvice(drive)}` : "";
  });
  record.reset = reset;
  reset.hidden = !hasSomethingToReset(d);
  record.commands.replaceChildren(el("div", { class: "commands" },
    el("button", { type: "button", text: "Start", "data-action": "start", onclick: start }),
    button("Stop", { action: "stop" }, `Stop ${name}?`),
    reset,
    hz,
    el("button", { type: "button", text: "Set", "data-action": "set_reference", onclick: setReference })));
}

const hasSomethingToReset = (d) => Boolean(d.fault || d.alarms.length);

function typedHz(text) {
  const value = Number.parseFloat(text.replace(",", "."));
  return Number.isFinite(value) && value >= 0 ? value : null;
}

// What a start without a typed speed runs at, in words: the commanded reference in Hz.
function startDetail(d) {
  const nominal = fleet.limits[d.name]?.nominal_frequency_hz;
  let pct = d.reference_pct;
  if (pct == null && !d.running) pct = 0;  // taken over standing: its reference is 0
  if (pct == null) return `It runs already; it keeps its present output, ${fmt(d.output_frequency_hz, 2)} Hz.`;
  if (pct < 0.005) {
    return "Its reference is 0 Hz: the motor will be powered but will not turn. " +
      "To start at a speed, type it in Hz beside the buttons first.";
  }
  const speed = nominal ? `${fmt((pct * nominal) / 100, 2)} Hz (${fmt(pct)} %)` : `${fmt(pct)} % of its nominal frequency`;
  return `It will run at its present reference, ${speed}.`;
}

function confirmCommand(name, body, question, detail = "") {
  const dialog = $("confirm");
  if (dialog.open) return;
  $("confirm-text").textContent = question;
  $("confirm-detail").textContent = detail;
  $("confirm-detail").hidden = !detail;
  dialog.returnValue = "";
  dialog.onclose = async () => {
    if (dialog.returnValue !== "ok") return;
    const response = await api(`/api/v1/drives/${encodeURIComponent(name)}/commands`,
                               { method: "POST", body: JSON.stringify(body) });
    const result = await response.json().catch(() => ({}));
    const outcome = result.outcome || `HTTP ${response.status}`;
    const reason = result.reason || result.detail || "";
    toast(`${name}: ${body.action} → ${outcome}${reason ? ` — ${reason}` : ""}`, !response.ok);
  };
  dialog.showModal();
  dialog.querySelector('button[value="cancel"]').focus();  // a stray Enter cancels
}

// -- lines --------------------------------------------------------------------------------

const LINE_FACTS = [
  ["requests", (s) => s.requests], ["replies", (s) => s.replies], ["timeouts", (s) => s.timeouts],
  ["errors", (s) => sumOf(s, ["checksum_errors", "malformed", "unexpected"])],
  ["utilisation", (s) => (s.utilisation != null ? `${fmt(s.utilisation * 100)} %` : null)],
  ["mean latency", (s) => (s.latency_s && s.latency_s.count
    ? `${fmt((s.latency_s.sum / s.latency_s.count) * 1000, 2)} ms` : null)],
];

function sumOf(stats, keys) {
  const present = keys.filter((k) => typeof stats[k] === "number");
  return present.length ? present.reduce((total, k) => total + stats[k], 0) : null;
}

// A USB adapter holds short replies back for its latency timer: above 1 ms it costs the line
// transactions, so the card says so (the daemon has logged the udev rule that fixes it).
function adapterText(adapter) {
  const name = adapter.by_id ? adapter.by_id.split("/").pop() : adapter.device;
  const latency = adapter.latency_ms == null ? "no latency timer" : `latency ${adapter.latency_ms} ms`;
  return [name, adapter.driver, latency].filter(Boolean).join(" · ");
}

function renderAdapter(card, adapter) {
  if (!card.adapter) {
    card.adapter = el("div", { class: "muted small", "data-testid": "adapter" });
    card.where.after(card.adapter);
  }
  put(card.adapter, adapter ? adapterText(adapter) : "");
  card.adapter.hidden = !adapter;
  const slow = Boolean(adapter && adapter.latency_ms > 1);
  card.adapter.classList.toggle("warn", slow);
  card.adapter.title = slow ? "the adapter's latency timer slows every reply: set it to 1 ms (udev rule in the log)" : "";
}

function renderLines() {
  const box = $("lines");
  for (const bus of fleet.buses.values()) {
    let card = cards.get(bus.name);
    if (!card) {
      card = { pill: el("span", { class: "pill" }), where: el("div", { class: "muted small" }), facts: new Map() };
      const list = el("dl", { class: "facts" });
      for (const [label] of LINE_FACTS) {
        const value = el("dd");
        card.facts.set(label, value);
        list.append(el("dt", { text: label }), value);
      }
      card.node = el("div", { class: "line-card", "data-bus": bus.name },
        el("h3", {}, el("button", { type: "button", class: "link", text: bus.name, "data-testid": "open-line",
                                    onclick: () => { location.hash = `line=${encodeURIComponent(bus.name)}`; } }),
           card.pill),
        card.where, list);
      cards.set(bus.name, card);
      box.append(card.node);
    }
    const stats = bus.stats || {};
    // line_silent and down_reason come with the line-fault statistics where the bus has them
    const silent = bus.up && stats.line_silent === true;
    put(card.pill, !bus.up ? "down" : silent ? "silent" : "up");
    card.pill.className = `pill ${!bus.up ? "pill-down" : silent ? "pill-warn" : "pill-up"}`;
    card.pill.title = silent ? "every drive fell silent together: cable, adapter or power?" : (stats.down_reason || "");
    put(card.where, [bus.port, bus.protocol, bus.baudrate && `${bus.baudrate} Bd`, !bus.up && stats.down_reason]
      .filter(Boolean).join(" · "));
    renderAdapter(card, bus.adapter);
    for (const [label, pick] of LINE_FACTS) put(card.facts.get(label), String(pick(stats) ?? "–"));
  }
}

// -- the gateway's own servers ------------------------------------------------------------

const STATUS_EVERY_MS = 5000;  // sessions come and go rarely: the status is asked for, not streamed
const gatewayShown = { shown: {} };  // what the sessions table shows

// The OPC UA server (when the config has one): whether its process serves, and who is
// connected to it — SCADA clients, with the user each logged in as.
async function loadStatus() {
  let status;
  try {
    const response = await api("/api/v1/status");
    if (!response.ok) return;
    status = await response.json();
  } catch (error) {
    return;  // the daemon is away: the connection pill says so
  }
  renderOpcua(status.opcua);
}

function renderOpcua(opcua) {
  $("gateway-section").hidden = !opcua;
  if (!opcua) return;
  put($("opcua-pill"), opcua.up ? "up" : "down");
  $("opcua-pill").className = `pill ${opcua.up ? "pill-up" : "pill-down"}`;
  const restarts = opcua.restarts ? `restarted ${opcua.restarts}×` : "";
  const count = `${opcua.sessions.length} session${opcua.sessions.length === 1 ? "" : "s"}`;
  put($("opcua-where"), [opcua.listen, count, restarts].filter(Boolean).join(" · "));
  const body = $("opcua-sessions").tBodies[0];
  const texts = opcua.sessions.map((s) => [s.user ?? "anonymous", s.client, s.application || "–",
    s.security, s.since ? new Date(s.since).toLocaleString() : "–"]);
  replaceIf(gatewayShown, "sessions", JSON.stringify(texts), body,
            () => texts.map((cells) => el("tr", { "data-testid": "opcua-session" },
              ...cells.map((text) => el("td", { text })))));
}

// -- events -------------------------------------------------------------------------------

// A journal record as [stamp, text, class]: drive events as the stream tells them.
function journalEntry(r) {
  const message = {
    alarm: { type: "condition" }, warning: { type: "condition" },
    online: { type: "availability", online: true }, offline: { type: "availability", online: false },
    command: { type: "command", command: { action: r.action, actor: r.actor }, result: { outcome: r.outcome, reason: r.reason } },
  }[r.kind];
  const where = [r.bus, r.drive].filter(Boolean).join("/");
  const text = message ? eventText({ ...r, ...message })
    : [`${where ? `${where}: ` : ""}${r.kind.replace("_", " ")}${r.outcome ? ` ${r.outcome}` : ""}` +
       `${r.verdict ? ` ${r.verdict}` : ""}${r.reason ? ` (${r.reason})` : ""}`, ""];
  return [clock(seconds(r.at)), ...text];
}

// The event list from the journal: what happened before this page (or the daemon) started.
async function loadJournal() {
  const response = await api(`/api/v1/events?limit=${EVENTS_KEPT}`);
  if (!response.ok) return;
  const entries = (await response.json()).map(journalEntry).reverse();
  $("events").replaceChildren(...entries.map(([stamp, text, cls]) => el("li", { class: cls, text: `${stamp} ${text}` })));
}

function logEvent(text, cls = "", drive = null) {
  const stamp = new Date().toLocaleTimeString();
  const list = $("events");
  list.prepend(el("li", { class: cls, text: `${stamp} ${text}` }));
  while (list.children.length > EVENTS_KEPT) list.lastChild.remove();
  if (!drive) return;
  const kept = driveEvents.get(drive) || [];
  kept.unshift([stamp, text, cls]);
  kept.length = Math.min(kept.length, DRIVE_EVENTS_KEPT);
  driveEvents.set(drive, kept);
  if (detail && detail.kind === "drive" && detail.name === drive) renderDriveEvents(drive);
}

let toastTimer = 0;
function toast(text, bad = false) {
  const box = $("toast");
  box.textContent = text;
  box.className = bad ? "toast bad" : "toast";
  box.hidden = false;
  clearTimeout(toastTimer);
  toastTimer = setTimeout(() => { box.hidden = true; }, 6000);
}

// -- the drive view -------------------------------------------------------------------------

async function openDrive(name) {
  closeDetail();
  const drive = fleet.drives.get(name);
  $("dv-name").textContent = name;
  $("dv-where").textContent = drive ? `${drive.bus} · address ${drive.address} · ${drive.protocol} · ${drive.control}` : "";
  $("dv-read-result").textContent = "";
  detail = { kind: "drive", name, charts: [], t: [], series: [], shown: {} };
  showView("drive-view");
  if (drive) updateDriveView(drive);
  renderDriveEvents(name);
  const current = detail;
  const response = await api(`/api/v1/drives/${encodeURIComponent(name)}/history`);
  if (detail !== current) return;  // another view was opened meanwhile
  if (!response.ok) { $("dv-charts").textContent = `No history: HTTP ${response.status}`; return; }
  const history = await response.json();
  // the journal's record of this drive's events (from before a restart too), newest first
  const journal = await api(`/api/v1/events?drive=${encodeURIComponent(name)}&limit=${DRIVE_EVENTS_KEPT}`);
  if (journal.ok) driveEvents.set(name, (await journal.json()).map(journalEntry).reverse());
  renderDriveEvents(name);
  current.t = history.t;
  current.series = history.series;
  buildCharts(current, $("dv-charts"), history.series.map((s) => [s.key,
    s.key === "output_frequency_hz" ? s.name : valueLabel(s.name, s.unit), s.unit]));
}

function updateDriveView(d) {
  replaceIf(detail, "state", JSON.stringify(stateParts(d)), $("dv-state"), () => pillNodes(stateParts(d)));
  const facts = [
    ["status word", d.status_word == null ? "–" : `0x${d.status_word.toString(16).toUpperCase().padStart(4, "0")}`],
    ["bits", d.status_word == null ? "–" : d.status_word.toString(2).padStart(16, "0").replace(/(.{4})(?=.)/g, "$1 ")],
    ["bits set", (d.status_bits || []).map((b) => b.replaceAll("_", " ")).join(", ") || "none"],
    ["online", d.online ? "yes" : "no"], ["running", d.running ? "yes" : "no"],
    ["direction", d.direction], ["at reference", d.at_reference ? "yes" : "no"],
    ["fault", d.fault ? "yes" : "no"], ["warning", d.warning ? "yes" : "no"],
    ["output frequency", `${fmt(d.output_frequency_hz, 2)} Hz`],
    ["frequency read at", d.output_frequency_updated_at ? clock(seconds(d.output_frequency_updated_at)) : "–"],
    ["reference", d.reference_pct != null ? `${fmt(d.reference_pct)} %` : "not commanded"],
    ["last reply", d.updated_at ? clock(seconds(d.updated_at)) : "–"],
  ];
  replaceIf(detail, "status", JSON.stringify(facts), $("dv-status"),
            () => facts.flatMap(([k, v]) => [el("dt", { text: k }), el("dd", { text: v })]));
  put($("dv-watchdog"), watchdogText(d));
  const values = Object.entries(d.values || {}).map(([param, v]) => [
    `${v.name ? valueLabel(v.name, v.unit) : param} (${param})`,
    v.texts ? (v.texts.length ? v.texts.join(", ") : "none") : `${fmtValue(v.value)}${v.unit ? ` ${v.unit}` : ""}`,
    v.updated_at ? `read at ${clock(seconds(v.updated_at))}` : "",
  ]);
  replaceIf(detail, "values", JSON.stringify(values), $("dv-values"),
            () => values.flatMap(([k, v, title]) => [el("dt", { text: k }), el("dd", { text: v, title })]));
  const conditions = [
    ...d.alarms.map((a) => ["alarm", `alarm ${a.code}: ${a.text}`]),
    ...d.warnings.map((w) => ["warning", `warning ${w.code}: ${w.text}`]),
  ];
  replaceIf(detail, "conditions", JSON.stringify(conditions), $("dv-conditions"), () => (conditions.length
    ? conditions.map(([cls, text]) => el("li", { class: cls, text }))
    : [el("li", { class: "muted", text: "none active" })]));
}

function renderDriveEvents(name) {
  const kept = driveEvents.get(name) || [];
  $("dv-events").replaceChildren(...kept.map(([stamp, text, cls]) => el("li", { class: cls, text: `${stamp} ${text}` })));
}

// A drive message for the open view: one more point on its charts.
function sampleDrive(d) {
  const at = seconds(d.updated_at) ?? Date.now() / 1000;
  if (!detail.charts.length) return;
  const values = { output_frequency_hz: d.online ? d.output_frequency_hz : null };
  for (const [param, v] of Object.entries(d.values || {})) values[param] = d.online && !v.texts ? v.value : null;
  addPoint(detail, at, detail.series.map((s) => values[s.key] ?? null));
}

async function readParameter(event) {
  event.preventDefault();
  const name = detail && detail.kind === "drive" ? detail.name : null;
  const param = $("dv-param").value.trim();
  if (!name || !param) return;
  const out = $("dv-read-result");
  out.textContent = `reading ${param}…`;
  const response = await api(`/api/v1/drives/${encodeURIComponent(name)}/parameters/${encodeURIComponent(param)}`);
  const result = await response.json().catch(() => ({}));
  if (response.ok) out.textContent = `${param} = ${fmtValue(result.value)}${result.unit ? ` ${result.unit}` : ""} (${new Date().toLocaleTimeString()})`;
  else out.textContent = `${param}: ${result.outcome || `HTTP ${response.status}`}${result.reason || result.detail ? ` — ${result.reason || result.detail}` : ""}`;
}

// -- the line view ------------------------------------------------------------------------------

const LINE_SERIES = [
  ["requests_per_s", "Requests", "/s"], ["timeouts_per_s", "Timeouts", "/s"],
  ["errors_per_s", "Errors", "/s"],
];

async function openLine(name) {
  closeDetail();
  const bus = fleet.buses.get(name);
  $("lv-name").textContent = name;
  $("lv-where").textContent = bus ? [bus.port, bus.protocol, bus.baudrate && `${bus.baudrate} Bd`].filter(Boolean).join(" · ") : "";
  detail = { kind: "line", name, charts: [], t: [], series: LINE_SERIES.map(([key]) => ({ key, data: [] })),
             shown: {} };
  showView("line-view");
  updateLineView();
  const current = detail;
  const response = await api(`/api/v1/buses/${encodeURIComponent(name)}/history`);
  if (detail !== current) return;
  if (!response.ok) { $("lv-charts").textContent = `No history: HTTP ${response.status}`; return; }
  const history = await response.json();
  current.t = history.t;
  current.series = LINE_SERIES.map(([key]) => ({ key, data: history.series[key] || [] }));
  buildCharts(current, $("lv-charts"), LINE_SERIES);
}

// Every statistic the line reports, including ones this page does not know by name.
function updateLineView() {
  const bus = fleet.buses.get(detail.name);
  if (!bus) return;
  const facts = [["port", bus.up ? "up" : "down"]];
  for (const [key, value] of Object.entries(bus.stats || {})) {
    if (typeof value === "number") {
      const text = key === "utilisation" ? `${fmt(value * 100)} %` : Number.isInteger(value) ? String(value) : fmtValue(value);
      facts.push([key.replaceAll("_", " "), text]);
    }
    else if (typeof value === "boolean") facts.push([key.replaceAll("_", " "), value ? "yes" : "no"]);
    else if (typeof value === "string") facts.push([key.replaceAll("_", " "), value]);
  }
  replaceIf(detail, "stats", JSON.stringify(facts), $("lv-stats"),
            () => facts.flatMap(([k, v]) => [el("dt", { text: k }), el("dd", { text: v })]));
}

// A stats message for the open line: rates since the previous one.
function sampleLine(bus) {
  const stats = bus.stats, now = Date.now() / 1000, last = detail.lastStats;
  detail.lastStats = { at: now, stats };
  if (!last || !detail.charts.length) return;
  const span = now - last.at;
  const rate = (keys) => Math.max(0, (sumOf(stats, keys) - sumOf(last.stats, keys)) / span);
  addPoint(detail, now, [rate(["requests"]), rate(["timeouts"]), rate(["checksum_errors", "malformed", "unexpected"])]);
}

// -- charts (uPlot, served by the daemon) -----------------------------------------------------

function buildCharts(state, box, specs) {
  box.replaceChildren();
  if (typeof uPlot === "undefined") { box.textContent = "The chart library did not load."; return; }
  // every holder first, so each is measured in the finished grid
  const holders = specs.map(([key]) => box.appendChild(el("div", { class: "chart", "data-series": key })));
  state.charts = specs.map(([key, title, unit], i) => {
    const named = !unit || unit === "/s" || title.includes(`[${unit}]`);
    const opts = {
      title: named ? title : `${title} [${unit}]`,
      width: chartWidth(holders[i]), height: 200,
      // at least a minute wide, so a few points do not spread over years
      scales: { x: { time: true, range: xRange } },
      legend: { show: false },
      series: [{}, { label: title, stroke: "#2b6cb0", width: 1.5, spanGaps: false }],
      axes: [
        { label: "time", labelSize: 18, size: 40 },
        { label: unit || "", labelSize: 18, size: 55 },
      ],
    };
    return new uPlot(opts, [state.t, state.series[i].data], holders[i]);
  });
}

function xRange(u, min, max) {
  if (min == null || max == null) { const now = Date.now() / 1000; return [now - 60, now]; }
  return [Math.min(min, max - 60), max];
}

const chartWidth = (holder) => Math.max(240, holder.clientWidth - 12);

function addPoint(state, at, values) {
  state.t.push(at);
  state.series.forEach((s, i) => s.data.push(values[i]));
  const from = at - WINDOW_S;
  let drop = 0;
  while (drop < state.t.length && state.t[drop] < from) drop++;
  if (drop) { state.t.splice(0, drop); for (const s of state.series) s.data.splice(0, drop); }
  state.charts.forEach((chart, i) => chart.setData([state.t, state.series[i].data]));
}

function resizeCharts() {
  if (!detail) return;
  for (const chart of detail.charts) {
    const holder = chart.root.parentElement;
    chart.setSize({ width: chartWidth(holder), height: 200 });
  }
}

function closeDetail() {
  if (detail) for (const chart of detail.charts) chart.destroy();
  detail = null;
}

// -- views and start -------------------------------------------------------------------------

function showView(id) {
  for (const name of ["fleet-view", "drive-view", "line-view"]) $(name).hidden = name !== id;
  window.scrollTo(0, 0);
}

function route() {
  if (takeTokenFromFragment()) { restart(); return; }
  const match = location.hash.match(/^#(drive|line)=(.+)$/);
  if (match && match[1] === "drive") openDrive(decodeURIComponent(match[2]));
  else if (match) openLine(decodeURIComponent(match[2]));
  else { closeDetail(); showView("fleet-view"); }
}

async function start() {
  let problem;
  try {
    problem = await identify();
  } catch (error) {
    setConnection("daemon unreachable", "pill-down");
    retry();
    return;
  }
  if (problem) { setConnection(problem, "pill-down"); return; }
  connect();
}

// A new token: drop the stream that was opened with the old one and start over.
function restart() {
  clearTimeout(retryTimer);
  retryMs = 500;
  const old = socket;
  socket = null;
  if (old) old.close();
  start();
}

function setupTokenDialog() {
  const dialog = $("token-dialog");
  $("token-button").onclick = () => { $("token-input").value = token || ""; dialog.showModal(); };
  dialog.onclose = () => {
    if (dialog.returnValue === "save") token = $("token-input").value.trim() || null;
    else if (dialog.returnValue === "clear") token = null;
    else return;
    if (token) sessionStorage.setItem("fcmaster.token", token);
    else sessionStorage.removeItem("fcmaster.token");
    restart();
  };
}

takeTokenFromFragment();
setupTokenDialog();
$("dv-read").addEventListener("submit", readParameter);
window.addEventListener("hashchange", route);
window.addEventListener("resize", () => { clearTimeout(resizeCharts.timer); resizeCharts.timer = setTimeout(resizeCharts, 150); });
setInterval(() => { for (const [name, record] of rows) markStale(record, fleet.drives.get(name)); }, 2000);
route();
start();
loadStatus();
setInterval(loadStatus, STATUS_EVERY_MS);
