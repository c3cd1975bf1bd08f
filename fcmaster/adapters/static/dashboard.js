// fcmaster dashboard: a live view of the fleet over /api/v1/stream, no build step.
// Everything text-like goes in through textContent, never innerHTML: drive names and
// alarm texts come from the plant.
"use strict";

const TREND_POINTS = 240;      // samples kept per drive (about two minutes)
const TREND_STEP_MS = 500;     // at most one sample per drive per half second
const EVENTS_KEPT = 100;

const fleet = { drives: new Map(), buses: new Map(), trends: new Map() };
let token = sessionStorage.getItem("fcmaster.token");
let role = null;
let socket = null;
let retryMs = 500;
const dirty = new Set();
let linesDirty = false;
let frame = 0;

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

function fmt(value, digits = 1) {
  if (value === null || value === undefined) return "–";
  if (typeof value !== "number") return String(value);
  return value.toFixed(digits);
}

// -- authentication -------------------------------------------------------------------

function takeTokenFromFragment() {
  const match = location.hash.match(/^#token=(.+)$/);
  if (!match) return;
  token = decodeURIComponent(match[1]);
  sessionStorage.setItem("fcmaster.token", token);
  history.replaceState(null, "", location.pathname + location.search);
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
    role = null;
    $("identity").textContent = "not signed in";
    showNotice("This dashboard needs a token: use the Token… button.");
    return false;
  }
  const who = await response.json();
  role = who.role;
  $("identity").textContent = `${who.name} · ${who.role}`;
  document.body.classList.toggle("operator", role === "operator");
  hideNotice();
  return true;
}

function showNotice(text) { $("notice").textContent = text; $("notice").hidden = false; }
function hideNotice() { $("notice").hidden = true; }

// -- the stream -------------------------------------------------------------------------

function connect() {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  const query = token ? `?token=${encodeURIComponent(token)}` : "";
  socket = new WebSocket(`${scheme}//${location.host}/api/v1/stream${query}`);
  socket.onopen = () => { retryMs = 500; setConnection("live", "pill-up"); };
  socket.onmessage = (event) => handle(JSON.parse(event.data));
  socket.onclose = () => {
    setConnection("reconnecting…", "pill-down");
    setTimeout(start, retryMs);
    retryMs = Math.min(retryMs * 2, 10000);
  };
}

function setConnection(text, cls) {
  const pill = $("connection");
  pill.textContent = text;
  pill.className = `pill ${cls}`;
}

function handle(message) {
  switch (message.type) {
    case "snapshot":
      fleet.drives.clear();
      for (const drive of message.drives) { fleet.drives.set(drive.name, drive); sample(drive); }
      fleet.buses.clear();
      for (const bus of message.buses) fleet.buses.set(bus.name, bus);
      $("drives").tBodies[0].replaceChildren();
      for (const name of fleet.drives.keys()) dirty.add(name);
      linesDirty = true;
      break;
    case "drive":
      fleet.drives.set(message.drive.name, message.drive);
      sample(message.drive);
      dirty.add(message.drive.name);
      break;
    case "line": {
      const bus = fleet.buses.get(message.bus) || { name: message.bus, drives: [] };
      bus.up = message.up;
      if (message.stats) bus.stats = message.stats;
      fleet.buses.set(message.bus, bus);
      linesDirty = true;
      if (message.reason) logEvent(`${message.bus}: ${message.up ? "up" : "down"} (${message.reason})`);
      break;
    }
    case "condition":
      logEvent(`${message.drive}: ${message.kind} ${message.code} ${message.text} ` +
               (message.active ? "raised" : "cleared"), message.active ? message.kind : "");
      break;
    case "availability":
      logEvent(`${message.drive} went ${message.online ? "online" : "offline"}`,
               message.online ? "" : "warning");
      break;
    case "command":
      logEvent(`${message.drive}: ${message.command.action} by ${message.command.actor || "?"} → ` +
               `${message.result.outcome}${message.result.reason ? ` (${message.result.reason})` : ""}`);
      break;
    case "dropped":
      logEvent(`${message.count} events missed (this page fell behind)`, "warning");
      break;
  }
  schedule();
}

function sample(drive) {
  let trend = fleet.trends.get(drive.name);
  if (!trend) { trend = []; fleet.trends.set(drive.name, trend); }
  const now = Date.now();
  const hz = drive.online ? (drive.output_frequency_hz ?? 0) : null;
  const last = trend[trend.length - 1];
  if (last && now - last[0] < TREND_STEP_MS) last[1] = hz;
  else trend.push([now, hz]);
  if (trend.length > TREND_POINTS) trend.splice(0, trend.length - TREND_POINTS);
}

function schedule() {
  if (!frame) frame = requestAnimationFrame(render);
}

// -- rendering ---------------------------------------------------------------------------

function render() {
  frame = 0;
  const body = $("drives").tBodies[0];
  for (const name of dirty) {
    const drive = fleet.drives.get(name);
    if (!drive) continue;
    const row = driveRow(drive);
    const old = body.querySelector(`tr[data-drive="${CSS.escape(name)}"]`);
    if (old) { keepInput(old, row); old.replaceWith(row); } else body.append(row);
  }
  dirty.clear();
  if (linesDirty) { renderLines(); linesDirty = false; }
  $("drive-count").textContent = `(${fleet.drives.size})`;
}

function keepInput(oldRow, newRow) {
  const before = oldRow.querySelector("input");
  const after = newRow.querySelector("input");
  if (before && after) {
    after.value = before.value;
    if (document.activeElement === before) setTimeout(() => after.focus(), 0);
  }
}

function stateText(d) {
  if (!d.online) return [["offline", "pill-down"]];
  const parts = [[d.running ? `running ${d.direction}` : "stopped", d.running ? "pill-up" : "pill-idle"]];
  if (d.fault) parts.push(["fault", "pill-down"]);
  if (d.warning) parts.push(["warning", "pill-warn"]);
  if (d.running && d.at_reference) parts.push(["at reference", "pill-idle"]);
  return parts;
}

function driveRow(d) {
  const row = el("tr", { "data-drive": d.name });
  if (!d.online) row.classList.add("offline");
  if (d.fault) row.classList.add("faulted");
  row.append(
    el("td", {}, el("span", { class: "name", text: d.name }),
       el("span", { class: "badge", text: d.control })),
    el("td", { class: "num", text: `${d.bus} · ${d.address}` }),
    el("td", { class: "state", "data-testid": "state" },
       ...stateText(d).map(([text, cls]) => el("span", { class: `pill ${cls}`, text }), " ")),
    el("td", { class: "num frequency", "data-testid": "frequency" },
       `${fmt(d.output_frequency_hz, 2)} Hz`,
       d.reference_pct != null ? el("div", { class: "muted", text: `ref ${fmt(d.reference_pct)} %` }) : null),
    el("td", {}, trendSvg(fleet.trends.get(d.name) || [])),
    el("td", { class: "values" }, ...Object.entries(d.values).map(([param, v]) =>
       el("span", { title: param, text: `${param} ${fmt(v.value, 2)} ${v.unit}` }))),
    el("td", {}, conditionList(d)),
  );
  if (role === "operator") {
    row.append(el("td", { class: "operator-only" },
                  d.control === "bus" ? commandCell(d) : "monitor only"));
  }
  return row;
}

function conditionList(d) {
  const list = el("ul", { class: "conditions", "data-testid": "conditions" });
  for (const a of d.alarms) list.append(el("li", { class: "alarm", text: `⚠ ${a.code} ${a.text}` }));
  for (const w of d.warnings) list.append(el("li", { class: "warning", text: `${w.code} ${w.text}` }));
  return list;
}

function trendSvg(points) {
  const ns = "http://www.w3.org/2000/svg";
  const svg = document.createElementNS(ns, "svg");
  svg.setAttribute("class", "trend");
  svg.setAttribute("viewBox", "0 0 120 28");
  svg.setAttribute("preserveAspectRatio", "none");
  const known = points.filter((p) => p[1] !== null);
  if (known.length > 1) {
    const t0 = known[0][0], t1 = known[known.length - 1][0];
    const top = Math.max(1, ...known.map((p) => p[1]));
    const line = document.createElementNS(ns, "polyline");
    line.setAttribute("points", known.map(([t, hz]) =>
      `${(((t - t0) / Math.max(1, t1 - t0)) * 118 + 1).toFixed(1)},${(27 - (hz / top) * 25).toFixed(1)}`).join(" "));
    svg.append(line);
  }
  return svg;
}

function commandCell(d) {
  const cell = el("div", { class: "commands" });
  const hz = el("input", { type: "number", step: "0.1", min: "0", placeholder: "Hz",
                           "data-testid": "reference", title: "reference in Hz" });
  const button = (label, body, verb) => el("button", {
    type: "button", text: label, "data-action": body.action,
    onclick: () => confirmCommand(d.name, body, verb),
  });
  cell.append(
    button("Start", { action: "start" }, `Start ${d.name}?`),
    button("Stop", { action: "stop" }, `Stop ${d.name}?`),
    button("Reset", { action: "reset" }, `Reset ${d.name}'s alarms?`),
    hz,
    el("button", { type: "button", text: "Set", "data-action": "set_reference", onclick: () => {
      const value = Number.parseFloat(hz.value);
      if (!Number.isFinite(value)) { toast("Enter a reference in Hz first", true); return; }
      confirmCommand(d.name, { action: "set_reference", frequency_hz: value },
                     `Set ${d.name}'s reference to ${value} Hz?`);
    } }),
  );
  return cell;
}

function confirmCommand(name, body, question) {
  const dialog = $("confirm");
  $("confirm-text").textContent = question;
  dialog.returnValue = "";
  dialog.onclose = async () => {
    if (dialog.returnValue !== "ok") return;
    const response = await api(`/api/v1/drives/${encodeURIComponent(name)}/commands`,
                               { method: "POST", body: JSON.stringify(body) });
    const result = await response.json().catch(() => ({}));
    const outcome = result.outcome || `HTTP ${response.status}`;
    toast(`${name}: ${body.action} → ${outcome}${result.reason ? ` — ${result.reason}` : ""}`,
          !response.ok);
  };
  dialog.showModal();
}

function renderLines() {
  const box = $("lines");
  box.replaceChildren();
  for (const bus of fleet.buses.values()) {
    const s = bus.stats || {};
    const latency = s.latency_s && s.latency_s.count ? (s.latency_s.sum / s.latency_s.count) * 1000 : null;
    const rows = [
      ["requests", s.requests], ["replies", s.replies], ["timeouts", s.timeouts],
      ["retries", s.retries], ["checksum errors", s.checksum_errors], ["noise bytes", s.noise_bytes],
      ["utilisation", s.utilisation != null ? `${fmt(s.utilisation * 100)} %` : null],
      ["mean latency", latency != null ? `${fmt(latency, 2)} ms` : null],
    ];
    const list = el("dl");
    for (const [label, value] of rows) list.append(el("dt", { text: label }), el("dd", { text: value ?? "–" }));
    box.append(el("div", { class: "line-card", "data-bus": bus.name },
      el("h3", {}, el("span", { text: bus.name }),
         el("span", { class: `pill ${bus.up ? "pill-up" : "pill-down"}`, text: bus.up ? "up" : "down" })),
      el("div", { class: "muted", text: [bus.port, bus.protocol, bus.baudrate && `${bus.baudrate} Bd`]
        .filter(Boolean).join(" · ") }),
      list));
  }
}

function logEvent(text, cls = "") {
  const list = $("events");
  list.prepend(el("li", { class: cls, text: `${new Date().toLocaleTimeString()} ${text}` }));
  while (list.children.length > EVENTS_KEPT) list.lastChild.remove();
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

// -- start ------------------------------------------------------------------------------

async function start() {
  try {
    if (!(await identify())) { setConnection("no token", "pill-down"); return; }
  } catch (error) {
    setConnection("daemon unreachable", "pill-down");
    setTimeout(start, retryMs);
    retryMs = Math.min(retryMs * 2, 10000);
    return;
  }
  connect();
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
    if (socket) { socket.onclose = null; socket.close(); }
    start();
  };
}

takeTokenFromFragment();
setupTokenDialog();
start();
