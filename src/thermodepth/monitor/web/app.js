// thermodepth dashboard: every page from the JSON API under /api, nothing else.
const main = document.getElementById("main");
const page = document.body.dataset.page;
let session = { auth: "open", name: null, csrf: null };

const esc = (s) => String(s ?? "").replace(/[&<>"']/g, (c) =>
  ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" })[c]);
const num = (v, d = 1) => (v === null || v === undefined || Number.isNaN(v) ? "–" : Number(v).toFixed(d));
// local time, 24 h, as a control room reads it: 2026-11-26 18:07:29
const when = (e) => {
  const d = new Date(e.time_utc), p = (n) => String(n).padStart(2, "0");
  return `${d.getFullYear()}-${p(d.getMonth() + 1)}-${p(d.getDate())} ${p(d.getHours())}:${p(d.getMinutes())}:${p(d.getSeconds())}`;
};

async function api(path, options = {}) {
  const r = await fetch(path, { credentials: "same-origin", ...options });
  if (r.status === 401) { location.href = `/login?next=${encodeURIComponent(location.pathname)}`; throw new Error("login"); }
  return r;
}
const json = async (path) => (await api(path)).json();

function badge(text, kind = text) { return `<span class="badge ${esc(kind)}">${esc(text)}</span>`; }
// an ROI's severity class (thermodepth.severity): its priority in colour, its words and delta-T
function severity(c) {
  if (!c) return "";
  const kind = c.priority === null ? "clear" : `p${Math.min(c.priority, 4)}`;
  const what = c.priority === null ? c.label : `P${c.priority} ${c.label}`;
  return `<span data-priority="${esc(c.priority ?? "")}">${badge(what, kind)} ΔT ${num(c.delta_t_c)} °C vs ${esc(c.relative_to)}</span>`;
}

function legend(range) {
  if (!range) return "";
  return `<div class="legend"><span>${num(range[0], 0)} °C</span><span class="bar"></span><span>${num(range[1], 0)} °C</span></div>
    <div class="legend"><span><i class="swatch" style="background:#008c8c"></i>no depth</span>
    <span><i class="swatch" style="background:#bfbfbf"></i>outside the thermal view</span>
    <span><i class="swatch" style="background:repeating-linear-gradient(45deg,#1acc1a 0 3px,#777 3px 6px)"></i>hidden</span>
    <span><i class="swatch" style="background:#ff00ff"></i>isotherm</span></div>`;
}

function hottest(rig) {
  const h = rig.hottest;
  if (!h) return `<div class="hottest">– <small>no hotspot</small></div>`;
  const where = h.position_m.map((x) => num(x, 2)).join(", ");
  const stale = rig.health === "stale" ? `, the last, ${ago(rig.last_frame_age_s)} ago` : "";
  return `<div class="hottest${stale ? " stale" : ""}" data-hottest="${h.max_c}">${num(h.max_c)} °C <small>at ${num(h.distance_m, 2)} m (${where} m)${h.resolvable ? "" : ", too small: reads low"}${esc(stale)}</small></div>`;
}

function alarmList(rig, withButtons) {
  if (!rig.active_alarms.length) return `<p class="muted">No active alarm.</p>`;
  return `<ul class="alarms">${rig.active_alarms.map((a) => `<li data-alarm="${esc(a.rule)}">${badge(a.level)}
    <strong>${esc(a.rule)}</strong>${a.fault ? ` <span class="muted">${esc(a.fault)}</span>` : ""}
    ${a.acknowledged ? `<span class="muted" data-acknowledged>acknowledged by ${esc(a.acknowledged.by)}</span>`
      : withButtons ? `<button data-ack="${esc(a.rule)}">Acknowledge</button>` : ""}</li>`).join("")}</ul>`;
}

// how long ago, as a person says it: 12 s, 4 min, 3 h 5 min, 2 d 4 h
const ago = (s) => {
  if (s === null || s === undefined || !Number.isFinite(s)) return "–";
  const m = Math.floor(s / 60), h = Math.floor(m / 60), d = Math.floor(h / 24);
  if (s < 60) return `${Math.floor(s)} s`;
  if (m < 60) return `${m} min`;
  if (h < 24) return `${h} h${m % 60 ? ` ${m % 60} min` : ""}`;
  return `${d} d${h % 24 ? ` ${h % 24} h` : ""}`;
};

// A live picture in its frame: <div class="pic"> with the <img> and a note over it.
function picFrame(cls, alt, id = "") {
  return `<div class="pic ${cls}"><img class="live"${id ? ` id="${id}"` : ""} alt="${esc(alt)}" hidden>
    <div class="note"><span class="nopic">no picture yet</span></div></div>`;
}

// Live pictures, fetched (a refusal seen as such, never a broken image): the next asked for
// once the last has arrived, at 2 Hz at most, and only while the rig's status (told by the
// page, tell(rig)) says there can be a new one: never before its first frame, not again
// after a refusal until its frame count has changed, once only while it is stale (its last
// picture, dimmed and dated).
function livePicture(box, url) {
  const img = box.querySelector("img"), note = box.querySelector(".note");
  let rig = null, shown = null, refusedAt = null, askedAt = null;
  const mayAsk = () => rig && rig.frames > 0 && rig.frames !== refusedAt
    && (rig.health !== "stale" || rig.frames !== askedAt);
  const draw = () => {
    const stale = rig?.health === "stale";
    box.classList.toggle("stale", Boolean(stale && shown));
    box.classList.toggle("empty", !shown);
    if (!shown) {
      const why = !rig || rig.frames > 0 ? "" : stale ? ` · no frame for ${ago(rig.last_frame_age_s)}` : " · waiting for its first frame";
      note.innerHTML = `<span class="nopic">no picture yet${esc(why)}</span>`;
    } else {
      note.innerHTML = stale ? `<span class="stale-note">stale · last frame ${esc(ago(rig.last_frame_age_s))} ago</span>` : "";
    }
  };
  const next = async () => {
    if (!document.body.contains(box)) return;
    const started = Date.now();
    if (mayAsk()) {
      askedAt = rig.frames;
      try {
        const r = await api(`${url}${url.includes("?") ? "&" : "?"}t=${started}`, { cache: "no-store" });
        if (r.ok) {
          const blob = await r.blob();
          const old = shown;
          shown = URL.createObjectURL(blob);
          img.src = shown;
          img.hidden = false;
          if (old) URL.revokeObjectURL(old);
          refusedAt = null;
        } else {
          refusedAt = rig.frames;
        }
      } catch (e) {
        if (e.message === "login") return;
      }
      draw();
    }
    setTimeout(next, Math.max(0, 500 - (Date.now() - started)));
  };
  next();
  return { tell(status) { rig = status; draw(); } };
}

async function whoAmI() {
  session = await json("/api/session");
  const who = document.getElementById("who");
  for (const a of document.querySelectorAll("[data-nav]")) a.classList.toggle("here", a.dataset.nav === page);
  if (session.auth === "session") {
    who.innerHTML = `${esc(session.name)} <button class="quiet" id="logout">Log out</button>`;
    document.getElementById("logout").onclick = async () => {
      await fetch("/logout", { method: "POST" });
      location.href = "/login";
    };
  }
}

async function acknowledge(rig, rule) {
  let by = session.name;
  if (!by) {
    by = localStorage.getItem("thermodepth-name") || prompt("Your name, recorded with the acknowledgement:");
    if (!by) return;
    localStorage.setItem("thermodepth-name", by);
  }
  const r = await api("/api/ack", {
    method: "POST",
    headers: { "Content-Type": "application/json", "X-CSRF-Token": session.csrf || "" },
    body: JSON.stringify({ rig, rule, by }),
  });
  if (!r.ok) alert((await r.json()).error);
}

// -- overview: every rig as a card ---------------------------------------------------------

async function overview() {
  const cards = new Map();
  main.innerHTML = `<div class="grid" id="rigs"></div>`;
  const grid = document.getElementById("rigs");
  const draw = async () => {
    const status = await json("/api/status");
    for (const rig of status.rigs) {
      let card = cards.get(rig.name);
      if (!card) {
        card = document.createElement("section");
        card.className = "card";
        card.dataset.rig = rig.name;
        card.innerHTML = `<div class="head"><h2><a href="/rig/${encodeURIComponent(rig.name)}">${esc(rig.name)}</a></h2>
          <span class="where">${esc(rig.location || "")}</span><span class="state"></span></div>
          ${picFrame("wide", `live overlay of ${rig.name}`)}
          <div class="body"><div class="reading"></div><div class="scale"></div><div class="alarms-here"></div></div>`;
        grid.append(card);
        cards.set(rig.name, card);
        card.picture = livePicture(card.querySelector(".pic"), `/api/rigs/${encodeURIComponent(rig.name)}/overlay.jpg?width=640`);
      }
      card.picture.tell(rig);
      card.querySelector(".state").innerHTML = badge(rig.health);
      card.querySelector(".reading").innerHTML = hottest(rig);
      card.querySelector(".scale").innerHTML = legend(rig.temp_range_c);
      card.querySelector(".alarms-here").innerHTML = alarmList(rig, false);
    }
  };
  await draw();
  setInterval(draw, 1000);
}

// -- a rig ---------------------------------------------------------------------------------

// A clock time (local, 24 h) of a Unix time in seconds: 14:07
const clock = (t) => { const d = new Date(t * 1000); return `${String(d.getHours()).padStart(2, "0")}:${String(d.getMinutes()).padStart(2, "0")}`; };

// A trend as a sparkline with its scale: the temperatures (°C) of its top and bottom at their
// right (its highest and lowest values, 0.1 °C outward, the scale at least SPARK_MIN_C tall:
// a sensor's noise is not drawn as a swing), when it begins and ends (clock times; a
// replay's own times: how long ago) under it. points: [{time_s, value}], value null where
// there was none.
const SPARK_MIN_C = 1;
function spark(points) {
  const p = points.filter((x) => x.value !== null && x.value !== undefined && Number.isFinite(x.value));
  if (p.length < 2) return `<span class="muted">${p.length ? `${num(p[0].value)} °C so far` : "–"}</span>`;
  const vs = p.map((x) => x.value), mid = (Math.min(...vs) + Math.max(...vs)) / 2;
  const lo = Math.floor(Math.min(...vs, mid - SPARK_MIN_C / 2) * 10) / 10;
  const hi = Math.ceil(Math.max(...vs, mid + SPARK_MIN_C / 2) * 10) / 10, span = hi - lo;
  const t0 = p[0].time_s, t1 = p.at(-1).time_s, dt = t1 - t0 || 1;
  const W = 200, H = 40, x = (t) => ((t - t0) / dt) * W, y = (v) => H - 3 - ((v - lo) / span) * (H - 6);
  const line = p.map((q) => `${x(q.time_s).toFixed(1)},${y(q.value).toFixed(1)}`).join(" ");
  const unix = t0 > 1e9; // a live rig's times; a replay's run from its own start
  return `<div class="trend" data-points="${p.length}">
    <svg class="spark" viewBox="0 0 ${W} ${H}" preserveAspectRatio="none" role="img"
      aria-label="from ${num(lo)} to ${num(hi)} °C over ${ago(t1 - t0)}">
      <line class="edge" x1="0" x2="${W}" y1="3" y2="3"/><line class="edge" x1="0" x2="${W}" y1="${H - 3}" y2="${H - 3}"/>
      <polyline points="${line}"/></svg>
    <span class="hi">${num(hi)} °C</span><span class="lo">${num(lo)} °C</span>
    <span class="when"><span>${unix ? clock(t0) : `−${ago(t1 - t0)}`}</span><span>${ago(t1 - t0)}</span><span>${unix ? clock(t1) : "last"}</span></span></div>`;
}

// -- lines and isotherms: a line's temperature against metres along the surface -------------

// A line's profile as a small chart: temperature (°C) against its position (m) along the
// surface, its hottest point marked, the scale's ends at its right; gaps (no depth or no
// temperature) left open.
function profileChart(p) {
  const pts = p.distance_m.map((d, i) => [d, p.temp_c[i]]);
  const ok = pts.filter(([d, t]) => Number.isFinite(d) && Number.isFinite(t));
  if (ok.length < 2) return `<span class="muted">no temperatures along it</span>`;
  const ts = ok.map(([, t]) => t), lo = Math.floor(Math.min(...ts)), hi = Math.max(Math.ceil(Math.max(...ts)), lo + 1);
  const len = p.length_m || ok.at(-1)[0] || 1, W = 300, H = 80;
  const x = (d) => (d / len) * W, y = (t) => H - 3 - ((t - lo) / (hi - lo)) * (H - 6);
  const runs = []; let run = [];
  for (const [d, t] of pts) {
    if (Number.isFinite(d) && Number.isFinite(t)) run.push(`${x(d).toFixed(1)},${y(t).toFixed(1)}`);
    else if (run.length) { runs.push(run); run = []; }
  }
  if (run.length) runs.push(run);
  const lines = runs.map((r) => `<polyline points="${r.join(" ")}"/>`).join("");
  const mark = Number.isFinite(p.max_at_m) ? `<circle class="max" cx="${x(p.max_at_m).toFixed(1)}" cy="${y(p.max_c).toFixed(1)}" r="3"/>` : "";
  return `<div class="trend profile"><svg class="spark" viewBox="0 0 ${W} ${H}" preserveAspectRatio="none" role="img"
      aria-label="${esc(p.name)}: ${num(lo)} to ${num(hi)} °C over ${num(len)} m">${lines}${mark}</svg>
    <span class="hi">${num(hi)} °C</span><span class="lo">${num(lo)} °C</span>
    <span class="when"><span>0 m</span><span></span><span>${num(len)} m</span></span></div>`;
}

function linesTable(shapes) {
  const lines = shapes.lines.map((p) => `<tr data-line="${esc(p.name)}"><td>${esc(p.name)}</td><td>${num(p.max_c)} °C at ${num(p.max_at_m)} m</td>
    <td>${num(p.length_m)} m${p.gap_px ? ` <span class="muted">(${p.gap_px} px without a reading)</span>` : ""}</td><td>${profileChart(p)}</td></tr>`).join("");
  const isos = shapes.isotherms.map((i) => `<tr data-isotherm="${esc(i.name)}"><td>${esc(i.name)}</td><td>above ${num(i.above_c)} °C</td>
    <td>${num(i.area_cm2)} cm²</td><td>${i.n ? `max ${num(i.max_c)} °C` : ""}</td></tr>`).join("");
  if (!lines && !isos) return "";
  return `<table>${lines ? `<tr><th>line</th><th>hottest</th><th>length</th><th>°C along it</th></tr>${lines}` : ""}
    ${isos ? `<tr><th>isotherm</th><th>band</th><th>area on the surface</th><th></th></tr>${isos}` : ""}</table>`;
}

async function rigPage() {
  const name = decodeURIComponent(location.pathname.slice("/rig/".length));
  document.title = `thermodepth · ${name}`;
  main.innerHTML = `<h2>${esc(name)} <span id="state"></span> <span class="muted" id="where"></span></h2>
    <div class="two"><div>${picFrame("wide", "live overlay", "overlay")}<div id="scale"></div></div>
    <div>${picFrame("thermal", "thermal image", "thermal")}<div id="reading"></div>
    <h3>Alarms</h3><div id="alarms"></div></div></div>
    <h3>Regions of interest</h3><div class="scroll"><table id="rois"></table></div>
    <div class="scroll" id="lines"></div>
    <h3>Recent events</h3><div class="scroll"><table id="events"></table></div>`;
  const q = encodeURIComponent(name);
  const pictures = [livePicture(document.querySelector(".pic.wide"), `/api/rigs/${q}/overlay.jpg`),
    livePicture(document.querySelector(".pic.thermal"), `/api/rigs/${q}/thermal.png`)];
  main.addEventListener("click", (e) => {
    const rule = e.target.dataset?.ack;
    if (rule) acknowledge(name, rule);
  });
  const draw = async () => {
    const status = await json("/api/status");
    const rig = status.rigs.find((r) => r.name === name);
    if (!rig) { main.innerHTML = `<p class="error">No rig ${esc(name)}.</p>`; return; }
    for (const p of pictures) p.tell(rig);
    document.getElementById("state").innerHTML = badge(rig.health);
    document.getElementById("where").textContent = rig.location || "";
    document.getElementById("reading").innerHTML = hottest(rig);
    document.getElementById("scale").innerHTML = legend(rig.temp_range_c);
    document.getElementById("alarms").innerHTML = alarmList(rig, true);
    const trend = await json(`/api/rigs/${q}/trend`);
    const rows = Object.entries(rig.rois).map(([roi, s]) => `<tr data-roi="${esc(roi)}"><td>${esc(roi)}</td>
      <td>${num(s.max_c)}</td><td>${num(s.mean_c)}</td><td>${num(s.min_c)}</td><td>${severity(s.severity)}</td>
      <td>${spark(trend.map((t) => ({ time_s: t.time_s, value: t.rois[roi] ?? null })))}</td></tr>`).join("");
    document.getElementById("rois").innerHTML = `<tr><th>ROI</th><th>max °C</th><th>mean °C</th><th>min °C</th><th>class</th><th>max, last hour</th></tr>${rows}`;
    const shapes = await api(`/api/rigs/${q}/lines`);
    document.getElementById("lines").innerHTML = shapes.ok ? linesTable(await shapes.json()) : "";
    const events = await json(`/api/events?rig=${q}&limit=20`);
    document.getElementById("events").innerHTML = eventRows(events);
  };
  await draw();
  setInterval(draw, 2000);
}

// -- events ----------------------------------------------------------------------------------

function eventRows(events) {
  const head = `<tr><th>when</th><th>rig</th><th>rule</th><th>level</th><th>state</th><th>value</th><th>what</th><th>evidence</th></tr>`;
  return head + events.map((e) => {
    const id = e.id;
    const have = id === undefined ? [] : e.evidence || [];
    const links = have.filter((n) => n !== "snapshot.png")
      .map((n) => `<a href="/api/events/${id}/${n}">${n === "clip.zip" ? "clip" : "PLY"}</a>`).join(" · ");
    const evidence = have.length
      ? `${have.includes("snapshot.png") ? `<a href="/api/events/${id}/snapshot.png"><img class="thumb" loading="lazy" src="/api/events/${id}/snapshot.png" alt="snapshot" onerror="this.replaceWith('overlay')"></a>` : ""}
         ${links}`
      : `<span class="muted">${e.clip ? (e.clip_kept === false ? "deleted" : "clip on its monitor") : "–"}</span>`;
    return `<tr data-event="${id ?? ""}"><td>${esc(when(e))}</td><td>${esc(e.rig)}</td><td>${esc(e.rule)}${e.fault ? ` <span class="muted">${esc(e.fault)}</span>` : ""}</td>
      <td>${badge(e.level)}</td><td>${badge(e.state, e.state === "alarm" || e.state === "escalated" ? e.level : e.state)}</td>
      <td>${e.value_c === null || e.value_c === undefined ? "" : `${num(e.value_c)} °C`}</td>
      <td>${esc(e.condition || "")}${e.by ? ` <span class="muted">by ${esc(e.by)}</span>` : ""}</td><td>${evidence}</td></tr>`;
  }).join("");
}

async function eventsPage() {
  const status = await json("/api/status");
  const options = (values) => `<option value="">all</option>${values.map((v) => `<option>${esc(v)}</option>`).join("")}`;
  main.innerHTML = `<div class="filters">
    <label>rig <select id="rig">${options(status.rigs.map((r) => r.name).concat(["monitor"]))}</select></label>
    <label>level <select id="level">${options(["warning", "alarm"])}</select></label>
    <label>state <select id="state">${options(["alarm", "escalated", "acknowledged", "clear"])}</select></label>
    </div><div class="scroll"><table id="events"></table></div><p><button class="quiet" id="older">Older</button></p>`;
  const table = document.getElementById("events");
  let shown = [];
  const query = (before) => {
    const p = new URLSearchParams({ limit: "50" });
    for (const f of ["rig", "level", "state"]) { const v = document.getElementById(f).value; if (v) p.set(f, v); }
    if (before) p.set("before", before);
    return `/api/events?${p}`;
  };
  const first = async () => { shown = await json(query()); table.innerHTML = eventRows(shown); };
  document.getElementById("older").onclick = async () => {
    const last = shown.filter((e) => e.id !== undefined).at(-1);
    if (!last) return;
    shown = shown.concat(await json(query(last.id)));
    table.innerHTML = eventRows(shown);
  };
  for (const f of ["rig", "level", "state"]) document.getElementById(f).onchange = first;
  await first();
  setInterval(async () => { if (shown.length <= 50) await first(); }, 2000);
}

// -- health ------------------------------------------------------------------------------------

async function healthPage() {
  const draw = async () => {
    const s = await json("/api/status");
    const row = (k, v) => `<tr><th>${esc(k)}</th><td>${esc(v)}</td></tr>`;
    // an output's status in words: nested figures (an RTSP server's streams) inline, none as –
    const said = (o) => Object.entries(o).map(([k, v]) => `${k.replace(/_/g, " ")} ${
      v === null ? "–" : typeof v === "object" ? (Object.keys(v).length ? `(${said(v)})` : "none") : v}`).join(", ");
    const rigs = s.rigs.map((r) => `<section class="card" data-rig="${esc(r.name)}"><div class="head"><h2>${esc(r.name)}</h2>${badge(r.health)}
      <span class="where">${esc(r.source)}</span></div><div class="body scroll"><table>
      ${row("state", r.state)}${row("frames/s", num(r.fps, 2))}${row("last frame", `${num(r.last_frame_age_s, 2)} s ago`)}
      ${row("frames", r.frames)}${row("reconnects", r.reconnects)}${row("stalls", r.stalls)}
      ${row("seconds without data", r.seconds_without_data)}${row("pairs dropped", r.dropped)}
      ${row("shutter (FFC)", r.ffc ? "closed" : "open")}${row("sensor (VOx)", r.vox_temp_c === null ? "not told" : `${num(r.vox_temp_c, 2)} °C`)}
      ${row("pipeline", `${num(r.pipeline_ms.median, 1)} ms median, ${num(r.pipeline_ms.p99, 1)} ms p99`)}
      ${row("last error", r.last_error || "–")}${row("last recovery", r.last_recovery || "–")}</table></div></section>`).join("");
    const st = s.storage;
    main.innerHTML = `<p>Up ${num(s.uptime_s / 3600, 2)} h, thermodepth ${esc(s.version)}.
      <a href="/metrics">Prometheus metrics</a> · <a href="/api/openapi.json">API schema</a></p>
      <div class="grid">${rigs}</div><h3>Storage</h3><table>
      ${row("path", st.path)}${row("free", `${num(st.free_bytes / 1e9, 1)} GB`)}${row("event store", `${num(st.event_store_bytes / 1e6, 1)} MB`)}
      ${row("events not yet stored", st.events_not_stored)}${st.events_lost ? row("events lost (memory full)", st.events_lost) : ""}${row("deleted", `${st.deleted.continuous} recordings, ${st.deleted.clips} clips`)}
      ${row("storage fault", st.fault ? "raised" : "no")}</table>
      <h3>Latency, capture to alarm</h3><table>${Object.entries(s.latency_s).map(([k, v]) =>
        row(k.replace("_", " "), v.n ? `${num(v.median * 1e3, 1)} ms median, ${num(v.p99 * 1e3, 1)} ms p99 (${v.n})` : "–")).join("")}</table>
      <h3>Workers</h3><table id="workers"><tr><th>worker</th><th>state</th><th>restarts</th><th>last error</th></tr>
      ${(s.workers || []).map((w) => `<tr data-worker="${esc(w.name)}" class="${w.healthy ? "" : "unwell"}"><td>${esc(w.name)}</td>
        <td>${esc(w.state)}${w.down_s ? esc(`, down ${num(w.down_s, 1)} s`) : ""}</td><td>${w.restarts}</td>
        <td>${esc(w.last_error || "–")}</td></tr>`).join("")}</table>
      <h3>Outputs</h3>${Object.keys(s.outputs || {}).length ? `<table id="outputs">${Object.entries(s.outputs).map(([name, o]) =>
        row(name, said(o))).join("")}</table>`
        : "<p>none (the dashboard and the log only)</p>"}`;
  };
  await draw();
  setInterval(draw, 2000);
}

await whoAmI();
({ overview, rig: rigPage, events: eventsPage, health: healthPage })[page]();
