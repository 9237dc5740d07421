// The sj300 workbench: one page over the gateway's API (/api/v1/) and event stream.
//
// Plain JavaScript, no build step: the page ships inside the Python package and
// plants are air-gapped. The only library is uPlot (static/vendor/uplot, with its
// licence), for the trend. Every value from the gateway is put into the page as
// text (textContent), never as markup.
//
// Routes (the part after #): "/" the overview, "/drive/LINE/NODE" a drive, the
// pages other scripts register (window.sj300Pages: trips.js's "/trips" and "/trip/ID").
// The event stream sends everything once when it opens, then each change; the
// page keeps the latest of each line and drive and redraws what is on screen
// once per animation frame.
"use strict";

(() => {
  const API = "/api/v1";
  const state = { gateway: null, lines: new Map(), drives: new Map() };
  // The logged-in user and the session's CSRF token (kept in memory only), and this
  // page's own id: the control lease belongs to this tab, not to the user's other tabs.
  const session = { user: null, csrf: null, checked: false };
  const TAB = Array.from(crypto.getRandomValues(new Uint8Array(6)), (b) => (b % 36).toString(36)).join("");
  const dirty = { lines: new Set(), drives: new Set(), scheduled: false };
  let view = null; // the page on screen: { kind, ... , update(kind, key) }

  // What tests and curious users can read from the console.
  window.workbench = { state, session, tab: TAB, events: 0, view: () => view };

  const $ = (root, selector) => root.querySelector(selector);
  const driveKey = (line, node) => `${line}/${node}`;

  function text(value, digits) {
    if (value === null || value === undefined) return "–";
    if (typeof value === "number") return digits === undefined ? String(value) : value.toFixed(digits);
    if (typeof value === "boolean") return value ? "yes" : "no";
    return String(value);
  }

  // "E07 over-voltage": the code the drive shows and its meaning (the protocol's
  // own name of the trip is in the API, and in the trip history's title).
  function tripText(trip) {
    if (!trip) return "";
    return trip.meaning ? `${trip.code} ${trip.meaning}` : trip.code;
  }

  function cell(row, field, value, cls) {
    const td = document.createElement("td");
    td.dataset.field = field;
    if (cls) td.className = cls;
    td.textContent = value;
    row.appendChild(td);
    return td;
  }

  // -- the event stream ---------------------------------------------------------------

  function connect() {
    const live = document.getElementById("live");
    const source = new EventSource(`${API}/events`);
    source.onopen = () => {
      live.textContent = "live";
      live.classList.remove("off");
    };
    source.onerror = () => {
      // EventSource reconnects by itself (the stream says retry: 2000).
      live.textContent = "reconnecting";
      live.classList.add("off");
    };
    source.addEventListener("gateway", (event) => {
      state.gateway = JSON.parse(event.data);
      const g = state.gateway;
      document.getElementById("gateway").textContent = `${g.id} · ${g.version}`;
      document.title = `${g.id} · sj300 workbench`;
      if (g.writes && !session.checked) checkSession();
      renderUser();
      if (view && view.gatewayChanged) view.gatewayChanged();
    });
    source.addEventListener("line", (event) => {
      const line = JSON.parse(event.data);
      state.lines.set(line.name, line);
      mark("lines", line.name);
    });
    source.addEventListener("drive", (event) => {
      const drive = JSON.parse(event.data);
      const key = driveKey(drive.line, drive.node);
      state.drives.set(key, drive);
      window.workbench.events += 1;
      // Every sample to the trend now: the redraw below keeps only the latest state of a
      // drive per animation frame, and a busy or hidden page skips frames.
      if (view && view.sample) view.sample(key, drive);
      mark("drives", key);
    });
  }

  // -- the session (only where the gateway serves writes) --------------------------------

  async function checkSession() {
    session.checked = true;
    const response = await fetch(`${API}/session`);
    if (response.ok) Object.assign(session, await response.json());
    renderUser();
    if (view && view.gatewayChanged) view.gatewayChanged();
  }

  function renderUser() {
    const box = document.getElementById("user");
    box.replaceChildren();
    if (!state.gateway || !state.gateway.writes) return;
    if (!session.user) {
      const link = document.createElement("a");
      link.href = "#/login";
      link.textContent = "Log in";
      box.appendChild(link);
      return;
    }
    const name = document.createElement("span");
    name.textContent = `${session.user} `;
    const out = document.createElement("button");
    out.type = "button";
    out.textContent = "Log out";
    out.addEventListener("click", async () => {
      await post(`${API}/logout`, {});
      session.user = session.csrf = null;
      renderUser();
      if (view && view.gatewayChanged) view.gatewayChanged();
    });
    box.append(name, out);
  }

  // A write: JSON, with the session's CSRF token; the answer's JSON, and ok or not.
  async function post(url, body) {
    const headers = { "Content-Type": "application/json" };
    if (session.csrf) headers["X-CSRF-Token"] = session.csrf;
    const response = await fetch(url, { method: "POST", headers, body: JSON.stringify(body) });
    let answer = {};
    try { answer = await response.json(); } catch (error) { answer = { error: String(error) }; }
    return { ok: response.ok, status: response.status, answer };
  }

  function loginPage(main) {
    main.replaceChildren(document.getElementById("login").content.cloneNode(true));
    const form = $(main, "form");
    const back = sessionStorage.getItem("sj300-after-login") || "#/";
    form.addEventListener("submit", async (event) => {
      event.preventDefault();
      const data = new FormData(form);
      const result = await post(`${API}/login`, { name: data.get("name"), password: data.get("password") });
      if (!result.ok) {
        $(main, '[data-field="error"]').textContent = result.answer.error || `refused (${result.status})`;
        return;
      }
      Object.assign(session, result.answer);
      renderUser();
      location.hash = back;
    });
    return { kind: "login", update() {}, close() {} };
  }

  function mark(kind, key) {
    dirty[kind].add(key);
    if (!dirty.scheduled) {
      dirty.scheduled = true;
      requestAnimationFrame(flush);
    }
  }

  function flush() {
    dirty.scheduled = false;
    const lines = [...dirty.lines];
    const drives = [...dirty.drives];
    dirty.lines.clear();
    dirty.drives.clear();
    if (!view) return;
    for (const key of lines) view.update("line", key);
    for (const key of drives) view.update("drive", key);
  }

  // -- the overview -------------------------------------------------------------------

  function overview(main) {
    main.replaceChildren(document.getElementById("overview").content.cloneNode(true));
    const lineBody = $(main, '[data-testid="lines"] tbody');
    const driveBody = $(main, '[data-testid="drives"] tbody');
    const lineRows = new Map();
    const driveRows = new Map();

    function rowFor(rows, body, key, order) {
      let row = rows.get(key);
      if (!row) {
        row = document.createElement("tr");
        row.dataset.key = key;
        rows.set(key, row);
        // Keep the gateway's order (lines as configured, nodes ascending).
        const keys = order();
        const next = keys.slice(keys.indexOf(key) + 1).map((k) => rows.get(k)).find(Boolean);
        body.insertBefore(row, next || null);
      }
      return row;
    }

    function renderLine(name) {
      const line = state.lines.get(name);
      if (!line) return;
      const row = rowFor(lineRows, lineBody, name, () => [...state.lines.keys()]);
      row.replaceChildren();
      const link = document.createElement("a");
      link.href = `#/line/${encodeURIComponent(line.name)}`;
      link.textContent = line.name;
      cell(row, "name", "").appendChild(link);
      cell(row, "protocol", line.protocol);
      cell(row, "connected", line.connected ? "up" : "down", line.connected ? "" : "bad");
      cell(row, "drives_online", `${line.drives_online} of ${line.drives}`, "num");
      cell(row, "utilisation",
        line.utilisation === null ? "–" : `${(100 * line.utilisation).toFixed(1)} %`, "num");
      for (const field of ["requests", "timeouts", "naks", "bad_frames", "early_frames", "stray_frames"]) {
        cell(row, field, text(line[field]), `num${line[field] && field !== "requests" ? " bad" : ""}`);
      }
      cell(row, "latency_mean_s",
        line.latency_mean_s === null ? "–" : `${(1000 * line.latency_mean_s).toFixed(1)} ms`, "num");
    }

    function renderDrive(key) {
      const drive = state.drives.get(key);
      if (!drive) return;
      const row = rowFor(driveRows, driveBody, key, () => [...state.drives.keys()]);
      row.replaceChildren();
      row.className = drive.tripped ? "tripped" : drive.online ? "" : "offline";
      const name = cell(row, "line", "");
      const link = document.createElement("a");
      link.href = `#/drive/${encodeURIComponent(drive.line)}/${drive.node}`;
      link.textContent = drive.line;
      name.appendChild(link);
      cell(row, "node", String(drive.node), "num");
      cell(row, "online", drive.online ? "online" : "offline", drive.online ? "" : "bad");
      cell(row, "state", text(drive.state));
      cell(row, "output_frequency_hz", text(drive.output_frequency_hz, 2), "num");
      cell(row, "set_frequency_hz", text(drive.set_frequency_hz, 2), "num");
      cell(row, "output_current_a", text(drive.output_current_a, 1), "num");
      cell(row, "output_voltage_v", text(drive.output_voltage_v, 1), "num");
      cell(row, "trip", tripText(drive.trip));
    }

    for (const name of state.lines.keys()) renderLine(name);
    for (const key of state.drives.keys()) renderDrive(key);
    return {
      kind: "overview",
      update(kind, key) {
        if (kind === "line") renderLine(key);
        else renderDrive(key);
      },
      close() {},
    };
  }

  // -- a drive ------------------------------------------------------------------------

  const SERIES = [
    { label: "output Hz", key: "output_frequency_hz", scale: "Hz", stroke: "#1f6feb" },
    { label: "current A", key: "output_current_a", scale: "A", stroke: "#d9480f" },
    { label: "voltage V", key: "output_voltage_v", scale: "V", stroke: "#2b8a3e" },
  ];

  function drivePage(main, line, node) {
    const key = driveKey(line, node);
    const base = `${API}/drives/${encodeURIComponent(line)}/${node}`;
    main.replaceChildren(document.getElementById("drive").content.cloneNode(true));
    const field = (name) => $(main, `[data-field="${name}"]`);
    field("title").textContent = `${line} · node ${node}`;
    field("csv").href = `${base}/trend.csv`;
    field("trip-records").href = `#/trips/${encodeURIComponent(line)}/${node}`;
    const chartBox = $(main, '[data-testid="trend"]');
    const data = [[], [], [], []];
    let capacity = 2000;
    let following = true;
    let chart = null;
    let tripsTime;
    let closed = false;

    function makeChart() {
      const width = Math.max(320, chartBox.clientWidth - 2);
      chart = new uPlot({
        width,
        height: 320,
        series: [
          { label: "time" },
          ...SERIES.map((s) => ({ label: s.label, scale: s.scale, stroke: s.stroke, width: 1.5, spanGaps: false })),
        ],
        scales: { x: { time: true } },
        axes: [
          {},
          { scale: "Hz", label: "Hz" },
          { scale: "A", label: "A", side: 1, grid: { show: false } },
          { scale: "V", label: "V", side: 1, grid: { show: false } },
        ],
        cursor: { drag: { x: true, y: false } },
        hooks: {
          setSelect: [() => { following = false; }],
        },
      }, data, chartBox);
      window.workbench.chart = chart;
    }

    function redraw() {
      if (chart) chart.setData(data, following);
      const n = data[0].length;
      field("trend-info").textContent = n
        ? `${n} samples since ${new Date(data[0][0] * 1000).toLocaleTimeString()}`
        : "no samples yet";
    }

    function append(drive) {
      const at = drive.monitor_time;
      const times = data[0];
      if (at === null || (times.length && at <= times[times.length - 1])) return;
      times.push(at);
      SERIES.forEach((s, i) => data[i + 1].push(drive[s.key]));
      if (times.length > capacity) for (const column of data) column.shift();
      redraw();
    }

    async function loadTrend() {
      const response = await fetch(`${base}/trend`);
      if (!response.ok) throw new Error(`trend: ${response.status}`);
      const trend = await response.json();
      if (closed) return;  // another page by now: its chart is gone
      capacity = trend.capacity;
      // Samples that came by the event stream while this loaded stay, after these.
      const later = data[0].map((t, i) => [t, data[1][i], data[2][i], data[3][i]])
        .filter((r) => !trend.time.length || r[0] > trend.time[trend.time.length - 1]);
      data[0] = trend.time.slice();
      SERIES.forEach((s, i) => { data[i + 1] = trend[s.key].slice(); });
      for (const r of later) r.forEach((v, i) => data[i].push(v));
      redraw();
    }

    async function loadTrips() {
      const response = await fetch(`${base}/trips`);
      if (!response.ok) return;
      const log = await response.json();
      if (closed) return;
      const body = $(main, '[data-testid="trips"] tbody');
      body.replaceChildren();
      field("trips-info").textContent = log.time === null
        ? "not read yet"
        : `read ${new Date(log.time * 1000).toLocaleTimeString()}` +
          (log.total_count === null ? ""
            : `; ${log.total_count} trip${log.total_count === 1 ? "" : "s"} counted by the drive`);
      log.records.forEach((trip, i) => {
        const row = document.createElement("tr");
        cell(row, "index", String(i + 1), "num");
        cell(row, "code", trip.code).title = text(trip.name);
        cell(row, "meaning", text(trip.meaning));
        cell(row, "output_frequency_hz", text(trip.output_frequency_hz, 2), "num");
        cell(row, "output_current_a", text(trip.output_current_a, 1), "num");
        cell(row, "output_voltage_v", text(trip.output_voltage_v, 1), "num");
        cell(row, "run_time_h", text(trip.run_time_h), "num");
        cell(row, "details", trip.details.map((d) => `${d.name}: ${d.value}`).join("; "));
        body.appendChild(row);
      });
    }

    function renderStatus(drive) {
      const body = $(main, '[data-testid="status"] tbody');
      body.replaceChildren();
      const rows = [["state", text(drive.state)], ["running", text(drive.running)],
        ["tripped", text(drive.tripped)], ["protocol", drive.protocol], ["unit id", text(drive.unit)]];
      for (const [name, value] of Object.entries(drive.status || {})) rows.push([name, text(value)]);
      for (const [code, reading] of Object.entries(drive.parameters || {})) {
        rows.push([code, reading === null ? "–" : `${reading.value} ${reading.unit}`.trim()]);
      }
      for (const [name, value] of rows) {
        const row = document.createElement("tr");
        cell(row, "name", name);
        cell(row, "value", value);
        body.appendChild(row);
      }
    }

    function render() {
      const drive = state.drives.get(key);
      if (!drive) return;
      const badge = field("state");
      badge.textContent = text(drive.state);
      badge.className = `badge${drive.tripped ? " tripped" : ""}`;
      field("online").textContent = drive.online ? "online" : "offline";
      field("direction").textContent = text(drive.direction);
      field("output_frequency_hz").textContent = text(drive.output_frequency_hz, 2);
      field("set_frequency_hz").textContent = text(drive.set_frequency_hz, 2);
      field("output_current_a").textContent = text(drive.output_current_a, 1);
      field("output_voltage_v").textContent = text(drive.output_voltage_v, 1);
      field("output_torque_percent").textContent = text(drive.output_torque_percent, 0);
      field("power_kw").textContent = text(drive.power_kw, 2);
      const trip = field("trip");
      trip.textContent = drive.trip ? tripText(drive.trip) : "none";
      trip.className = drive.trip ? "bad" : "";
      renderStatus(drive);
      if (drive.trips_time !== tripsTime) {
        tripsTime = drive.trips_time;
        loadTrips().catch((error) => { field("trips-info").textContent = `not loaded: ${error}`; });
      }
    }

    // -- control (where the gateway grants it, to a logged-in user) ----------------------
    const control = $(main, '[data-testid="control"]');
    let heartbeat = null;
    let holding = false;

    function grant() {
      const g = state.gateway;
      if (!g || !g.writes) return null;
      const gl = g.lines.find((l) => l.name === line);
      if (!gl) return null;
      const grants = gl.grants.filter((x) => x.nodes.includes(node));
      return { lease_s: gl.lease_s, control: grants.some((x) => x.control) };
    }

    function showControl() {
      const allowed = grant();
      control.hidden = !(allowed && allowed.control && session.user);
      renderLease();
    }

    function renderLease() {
      const drive = state.drives.get(key);
      const holder = drive && drive.control ? drive.control.holder : null;
      const mine = holder !== null && holder === `http:${session.user}#${TAB}`;
      if (holding && holder !== null && !mine) stopHeartbeat("another client took control");
      const text = mine || holding
        ? "You have control: this page renews it while it is open. Close it, or lose the network, and the drive stops."
        : holder ? `Controlled by ${holder}.` : "Nobody controls this drive.";
      field("lease").textContent = text;
      for (const action of ["forward", "reverse", "frequency"]) {
        $(main, `[data-action="${action}"]`).disabled = !holding;
      }
      $(main, '[data-action="take"]').disabled = holding;
    }

    function stopHeartbeat(why) {
      holding = false;
      clearInterval(heartbeat);
      heartbeat = null;
      if (why) field("control-error").textContent = `control lost: ${why}`;
      renderLease();
    }

    async function command(path, body) {
      const result = await post(`${base}/${path}`, { tab: TAB, ...body });
      field("control-error").textContent = result.ok ? "" : result.answer.error || `refused (${result.status})`;
      return result;
    }

    async function take() {
      const allowed = grant();
      const result = await command("lease", {});
      if (!result.ok) return;
      holding = true;
      clearInterval(heartbeat);
      // Three heartbeats per lease: one late or lost does not lapse it.
      heartbeat = setInterval(async () => {
        const renewed = await command("lease", {});
        if (!renewed.ok) stopHeartbeat(renewed.answer.error || "refused");
      }, (allowed.lease_s * 1000) / 3);
      renderLease();
    }

    $(main, '[data-action="take"]').addEventListener("click", take);
    $(main, '[data-action="forward"]').addEventListener("click", () => command("run", { direction: "forward" }));
    $(main, '[data-action="reverse"]').addEventListener("click", () => command("run", { direction: "reverse" }));
    $(main, '[data-action="stop"]').addEventListener("click", () => command("stop", {}));
    $(main, '[data-action="frequency"]').addEventListener("click", () => {
      const text = field("hz").value.trim();
      const hz = Number(text);
      if (text === "" || !Number.isFinite(hz)) {  // Number("") is 0: never send that
        field("control-error").textContent = "enter a frequency in Hz first";
        return;
      }
      command("frequency", { hz });
    });

    // -- parameters: read all (progress), compare with a backup, edit what is granted ----------
    let backup = null;      // the drive's set as read: the sj300-params format
    let compared = null;    // the uploaded backup as the gateway read it: {parameters, absent}
    let reading = null;     // the EventSource of a read under way

    function granted(code) {
      const g = state.gateway;
      if (!g || !g.writes || !session.user) return false;
      const gl = g.lines.find((l) => l.name === line);
      return !!gl && gl.grants.some((x) => x.nodes.includes(node) && x.parameters.includes(code));
    }

    function readParameters() {
      if (reading) return;
      const bar = field("progress");
      field("params-error").textContent = "";
      bar.hidden = false;
      bar.value = 0;
      reading = new EventSource(`${base}/parameters`);
      reading.addEventListener("progress", (event) => {
        const p = JSON.parse(event.data);
        bar.max = p.total;
        bar.value = p.done;
        field("params-info").textContent = `${p.done} of ${p.total} read (${p.code})`;
      });
      reading.addEventListener("backup", (event) => {
        backup = JSON.parse(event.data);
        finishRead();
        field("params-info").textContent =
          `${backup.parameters.length} codes read at ${new Date(backup.taken_at).toLocaleTimeString()}`;
        const blob = new Blob([JSON.stringify(backup, null, 2) + "\n"], { type: "application/json" });
        const link = field("download");
        link.href = URL.createObjectURL(blob);
        link.download = `${line}-${node}-params.json`;
        link.hidden = false;
        renderParameters();
      });
      reading.addEventListener("error", (event) => {
        // The gateway's own "error" event carries data; a lost connection does not.
        const message = event.data ? JSON.parse(event.data).error : "the read stopped: the connection was lost";
        field("params-error").textContent = message;
        finishRead();
      });
    }

    function finishRead() {
      if (reading) reading.close();  // else EventSource would start the read again
      reading = null;
      field("progress").hidden = true;
    }

    async function compareWith(file) {
      field("params-error").textContent = "";
      const protocol = (state.drives.get(key) || {}).protocol || "";
      const response = await fetch(`${API}/parameters/check?protocol=${encodeURIComponent(protocol)}`, {
        method: "POST", headers: { "Content-Type": "application/json" }, body: await file.text(),
      });
      const answer = await response.json();
      if (!response.ok) {
        compared = null;
        field("params-error").textContent = `${file.name}: ${answer.error}`;
      } else {
        compared = answer;
        if (answer.node !== node) {
          field("params-error").textContent =
            `${file.name} was read from node ${answer.node}, this is node ${node}: compared all the same`;
        }
      }
      renderParameters();
    }

    function renderParameters() {
      const body = $(main, '[data-testid="parameter-table"] tbody');
      body.replaceChildren();
      if (!backup) return;
      const onlyDiff = field("only-diff").checked;
      let differences = 0;
      let restorable = 0;
      for (const p of backup.parameters) {
        const other = compared ? compared.parameters[p.code] : undefined;
        const otherAbsent = compared ? p.code in compared.absent : false;
        // Against the defaults (partial: the catalogue knows some), a code without one is
        // not compared; against a file, a code the file lacks differs.
        const compares = compared !== null && (!compared.partial || other !== undefined);
        const differs = compares && ((other ? other.raw : null) !== p.raw) && !(otherAbsent && p.raw === null);
        if (differs) differences += 1;
        if (differs && other && granted(p.code)) restorable += 1;
        if (onlyDiff && !differs) continue;
        const row = document.createElement("tr");
        row.dataset.code = p.code;
        if (differs) row.className = "changed";
        cell(row, "code", p.code);
        cell(row, "name", text(p.name));
        cell(row, "value", p.absent ? "absent" : text(p.value), "num");
        cell(row, "unit", text(p.unit));
        cell(row, "raw", text(p.raw), "num");
        const missing = compared && compared.partial ? "" : "not in the file";
        const shown = !compared ? "" : otherAbsent ? "absent" : other ? text(other.value === null ? other.raw : other.value) : missing;
        cell(row, "backup", shown, "num");
        const actions = cell(row, "actions", "");
        if (granted(p.code) && p.raw !== null) {
          const edit = document.createElement("button");
          edit.type = "button";
          edit.textContent = "edit";
          edit.dataset.testid = "edit";
          edit.addEventListener("click", () => editParameter(p));
          actions.appendChild(edit);
        }
        body.appendChild(row);
      }
      if (compared) {
        const against = compared.partial ? "the factory defaults the catalogue knows" : "the file";
        field("params-info").textContent = `${differences} differences with ${against}`;
      }
      const restore = $(main, '[data-action="restore"]');
      restore.hidden = restorable === 0;
      restore.textContent = `Write the compared values of granted parameters (${restorable})`;
    }

    async function writeParameter(p, body, description) {
      if (!confirm(`${line} node ${node}: ${description}\n\nWrite it to the drive?`)) return false;
      const result = await post(`${base}/parameter`, { tab: TAB, code: p.code, ...body });
      if (!result.ok) {
        field("params-error").textContent = `${p.code}: ${result.answer.error}`;
        return false;
      }
      return true;
    }

    async function editParameter(p) {
      const answer = prompt(`${p.code} ${p.name || ""}: new value${p.unit ? ` in ${p.unit}` : ""}`, String(p.value));
      if (answer === null) return;
      const value = Number(answer);
      if (answer.trim() === "" || !Number.isFinite(value)) {
        field("params-error").textContent = `${p.code}: ${answer} is not a number`;
        return;
      }
      const unit = p.unit ? ` ${p.unit}` : "";
      if (await writeParameter(p, { value }, `${p.code} ${p.name || ""}: ${p.value}${unit} → ${value}${unit}`)) {
        field("params-error").textContent = "";
        readParameters();  // the set as the drive holds it now
      }
    }

    async function restoreGranted() {
      const changes = backup.parameters.filter((p) => {
        const other = compared && compared.parameters[p.code];
        return other && other.raw !== p.raw && granted(p.code);
      });
      const lines = changes.map((p) => {
        const other = compared.parameters[p.code];
        return `${p.code} ${p.name || ""}: ${text(p.value)} → ${text(other.value === null ? other.raw : other.value)} ${p.unit || ""}`;
      });
      if (!confirm(`${line} node ${node}: write ${changes.length} values from the file?\n\n${lines.join("\n")}`)) return;
      const failed = [];
      for (const p of changes) {
        const result = await post(`${base}/parameter`, { tab: TAB, code: p.code, raw: compared.parameters[p.code].raw });
        if (!result.ok) failed.push(`${p.code}: ${result.answer.error}`);
      }
      field("params-error").textContent = failed.length
        ? `${failed.length} of ${changes.length} not written: ${failed.join("; ")}`
        : "";
      readParameters();
    }

    $(main, '[data-action="read-parameters"]').addEventListener("click", readParameters);
    $(main, '[data-action="defaults"]').addEventListener("click", async () => {
      const response = await fetch(`${base}/defaults`);
      compared = await response.json();
      renderParameters();
    });
    $(main, '[data-action="restore"]').addEventListener("click", restoreGranted);
    field("only-diff").addEventListener("change", renderParameters);
    field("compare-file").addEventListener("change", (event) => {
      const file = event.target.files[0];
      if (file) compareWith(file);
    });

    $(main, '[data-action="follow"]').addEventListener("click", () => {
      following = true;
      redraw();
    });
    makeChart();
    render();
    const now = state.drives.get(key);
    if (now) append(now);
    showControl();
    loadTrend().catch((error) => { field("trend-info").textContent = String(error); });
    return {
      kind: "drive",
      key,
      data,
      sample(changed, drive) {
        if (changed === key && !closed) append(drive);
      },
      update(kind, changed) {
        if (kind === "drive" && changed === key) {
          render();
          renderLease();
        }
      },
      gatewayChanged() {
        showControl();
        renderParameters();
      },
      close() {
        closed = true;
        stopHeartbeat();
        finishRead();
        if (chart) chart.destroy();
        window.workbench.chart = null;
      },
    };
  }

  // -- a line: its recent frames -------------------------------------------------------

  // The frames come from the gateway's record of the line, judged by the same
  // sniffer as `sj300 sniff`: fetched every second (the last 10 s), newest first.
  const FRAME_WINDOW_S = 10;
  const REFRESH_MS = 1000;

  function linePage(main, name) {
    main.replaceChildren(document.getElementById("line").content.cloneNode(true));
    const field = (f) => $(main, `[data-field="${f}"]`);
    const base = `${API}/lines/${encodeURIComponent(name)}`;
    field("title").textContent = name;
    const nodeSelect = field("node");
    fetch(`${API}/gateway`).then((r) => r.json()).then((gateway) => {
      const line = gateway.lines.find((l) => l.name === name);
      for (const node of line ? line.nodes : []) {
        const option = document.createElement("option");
        option.value = String(node);
        option.textContent = String(node);
        nodeSelect.appendChild(option);
      }
    }).catch(() => {});  // the filter stays at "all"; the frames say what is wrong
    const seconds = field("seconds");
    const pcapng = field("pcapng");
    const setLink = () => {
      const s = Math.min(300, Math.max(1, Number(seconds.value) || 60));
      pcapng.href = `${base}/capture.pcapng?seconds=${s}`;
    };
    seconds.addEventListener("input", setLink);
    setLink();
    let timer = null;
    let closed = false;

    function clock(t) {
      const d = new Date(t * 1000);
      return `${d.toLocaleTimeString([], { hour12: false })}.${String(d.getMilliseconds()).padStart(3, "0")}`;
    }

    function render(frames) {
      const body = $(main, '[data-testid="frames"] tbody');
      const onlyAnomalies = field("anomalies").checked;
      const shown = frames.filter((f) => !onlyAnomalies || f.anomalies.length).reverse();
      body.replaceChildren();
      for (const f of shown) {
        const row = document.createElement("tr");
        if (f.anomalies.length) row.className = "anomaly";
        cell(row, "time", clock(f.time));
        if (f.kind === "unanswered") {
          cell(row, "n", "");
          cell(row, "role", "—");
          cell(row, "node", text(f.node));
          cell(row, "summary", f.summary);
          cell(row, "text", "");
          cell(row, "answers", `#${f.request}`);
          cell(row, "latency_ms", "", "num");
        } else {
          cell(row, "n", String(f.n), "num");
          cell(row, "role", f.role);
          cell(row, "node", text(f.node));
          cell(row, "summary", f.summary).title = f.summary;
          cell(row, "text", f.text).title = f.text;
          cell(row, "answers", f.answers === null ? "" : `#${f.answers}`);
          cell(row, "latency_ms", f.latency_ms === null ? "" : `${f.latency_ms.toFixed(1)} ms`, "num");
        }
        cell(row, "flags", f.anomalies.join(", "));
        body.appendChild(row);
      }
      const flagged = frames.filter((f) => f.anomalies.length).length;
      field("info").textContent = `${frames.length} frames in the last ${FRAME_WINDOW_S} s, ${flagged} flagged`;
    }

    async function refresh() {
      if (closed) return;
      if (!field("paused").checked) {
        const node = nodeSelect.value;
        const query = `seconds=${FRAME_WINDOW_S}${node ? `&node=${node}` : ""}`;
        try {
          const response = await fetch(`${base}/frames?${query}`);
          const answer = await response.json();
          if (!closed) {
            if (response.ok) render(answer.frames);
            else field("info").textContent = answer.error;
          }
        } catch (error) {
          if (!closed) field("info").textContent = `the gateway did not answer: ${error}`;
        }
      }
      if (!closed) timer = setTimeout(refresh, REFRESH_MS);
    }

    nodeSelect.addEventListener("change", () => { clearTimeout(timer); refresh(); });
    field("anomalies").addEventListener("change", () => { clearTimeout(timer); refresh(); });
    refresh();
    return {
      kind: "line",
      update() {},
      close() {
        closed = true;
        clearTimeout(timer);
      },
    };
  }

  // -- the audit log ---------------------------------------------------------------------

  function auditPage(main) {
    main.replaceChildren(document.getElementById("audit").content.cloneNode(true));
    let closed = false;
    let timer = null;
    async function refresh() {
      try {
        const response = await fetch(`${API}/audit?limit=200`);
        const answer = await response.json();
        if (closed) return;
        $(main, '[data-field="kept"]').textContent = String(answer.kept);
        const body = $(main, '[data-testid="audit"] tbody');
        body.replaceChildren();
        for (const r of answer.records) {
          const row = document.createElement("tr");
          if (r.result !== "ok") row.className = "anomaly";
          cell(row, "time", new Date(r.time * 1000).toLocaleString());
          cell(row, "client", text(r.client));
          cell(row, "line", text(r.line));
          cell(row, "node", text(r.node), "num");
          cell(row, "what", text(r.what));
          cell(row, "old", text(r.old));
          cell(row, "new", text(r.new));
          cell(row, "result", r.result === "refused" ? r.reason : text(r.result));
          cell(row, "detail", text(r.detail === undefined ? "" : r.detail));
          body.appendChild(row);
        }
      } catch (error) {
        // The next refresh tries again; the table keeps what it showed.
      }
      if (!closed) timer = setTimeout(refresh, 2000);
    }
    refresh();
    return { kind: "audit", update() {}, close() { closed = true; clearTimeout(timer); } };
  }

  // -- routing ------------------------------------------------------------------------

  function route() {
    const main = document.getElementById("main");
    if (view) view.close();
    const drive = /^#\/drive\/([^/]+)\/(\d+)$/.exec(location.hash);
    const line = /^#\/line\/([^/]+)$/.exec(location.hash);
    const util = { $, cell, text, API, SERIES };
    const other = (window.sj300Pages || []).map((p) => [p, p.pattern.exec(location.hash)]).find(([, m]) => m);
    if (other) view = other[0].page(main, util, other[1]);
    else if (drive) view = drivePage(main, decodeURIComponent(drive[1]), Number(drive[2]));
    else if (line) view = linePage(main, decodeURIComponent(line[1]));
    else if (location.hash === "#/login") view = loginPage(main);
    else if (location.hash === "#/audit") view = auditPage(main);
    else view = overview(main);
    if (location.hash !== "#/login") sessionStorage.setItem("sj300-after-login", location.hash || "#/");
  }

  window.addEventListener("hashchange", route);
  connect();
  route();
})();
