// The workbench's Trips pages: the trip records the gateway keeps (issue 45).
//
// Routes: "#/trips" every record, newest first; "#/trips/LINE/NODE" one drive's;
// "#/trip/ID" one record: its trip, the chart of Hz, A and V across it with the
// trip's instant marked, the writes to the drive before it, and its downloads
// (JSON, CSV, the line's frames as pcapng). The records are the gateway's
// (GET /api/v1/trips...): this page only shows them.
//
// Loaded before app.js, which calls the pages registered here (window.sj300Pages)
// with its helpers (window.workbench.util) when a route matches.
"use strict";

(() => {
  const pages = (window.sj300Pages = window.sj300Pages || []);

  function listPage(main, util, line, node) {
    const { $, cell, text, API } = util;
    main.replaceChildren(document.getElementById("trips-list").content.cloneNode(true));
    const title = line === undefined ? "every drive" : `${line} · node ${node}`;
    $(main, '[data-field="title"]').textContent = title;
    let closed = false;
    let timer = null;
    async function refresh() {
      try {
        const query = line === undefined ? "" : `?line=${encodeURIComponent(line)}&node=${node}`;
        const response = await fetch(`${API}/trips${query}`);
        const answer = await response.json();
        if (closed) return;
        $(main, '[data-field="info"]').textContent = answer.recording
          ? `${answer.trips.length} record${answer.trips.length === 1 ? "" : "s"}`
          : "the gateway keeps no trip records ([recorder] enabled = false)";
        const body = $(main, '[data-testid="trip-list"] tbody');
        body.replaceChildren();
        for (const r of answer.trips) {
          const row = document.createElement("tr");
          const when = cell(row, "time", "");
          const link = document.createElement("a");
          link.href = `#/trip/${encodeURIComponent(r.id)}`;
          link.textContent = new Date(r.time * 1000).toLocaleString();
          when.appendChild(link);
          cell(row, "line", text(r.line));
          cell(row, "node", text(r.node), "num");
          cell(row, "code", text(r.code));
          cell(row, "meaning", text(r.meaning));
          cell(row, "seen_by", text(r.seen_by));
          cell(row, "bytes", `${Math.round(r.bytes / 1024)} KiB`, "num");
          body.appendChild(row);
        }
      } catch (error) {
        // The next refresh tries again; the table keeps what it showed.
      }
      if (!closed) timer = setTimeout(refresh, 5000);
    }
    refresh();
    return { kind: "trips", update() {}, close() { closed = true; clearTimeout(timer); } };
  }

  // A vertical line at the trip's instant, drawn over the chart.
  function marker(at) {
    return (u) => {
      const x = Math.round(u.valToPos(at, "x", true));
      const { ctx } = u;
      ctx.save();
      ctx.strokeStyle = "#c92a2a";
      ctx.lineWidth = 2 * devicePixelRatio;
      ctx.setLineDash([6 * devicePixelRatio, 4 * devicePixelRatio]);
      ctx.beginPath();
      ctx.moveTo(x, u.bbox.top);
      ctx.lineTo(x, u.bbox.top + u.bbox.height);
      ctx.stroke();
      ctx.restore();
    };
  }

  function recordPage(main, util, id) {
    const { $, cell, text, API, SERIES } = util;
    main.replaceChildren(document.getElementById("trip-record").content.cloneNode(true));
    const field = (name) => $(main, `[data-field="${name}"]`);
    const base = `${API}/trips/${encodeURIComponent(id)}`;
    field("json").href = base;
    field("csv").href = `${base}.csv`;
    field("pcapng").href = `${base}/frames.pcapng`;
    let closed = false;
    let chart = null;
    async function load() {
      const response = await fetch(base);
      if (closed) return;
      if (!response.ok) {
        field("error").textContent = `no such record (${response.status})`;
        return;
      }
      const record = await response.json();
      if (closed) return;
      const trip = record.trip;
      field("trip").textContent = trip ? (trip.meaning ? `${trip.code} ${trip.meaning}` : trip.code) : "trip (not named: no history read)";
      field("when").textContent = `Tripped ${new Date(record.time * 1000).toLocaleString()} (seen by the ${record.seen_by}).`;
      const drive = field("drive");
      drive.href = `#/drive/${encodeURIComponent(record.line)}/${record.node}`;
      drive.textContent = `${record.line} · node ${record.node}`;
      if (trip) {
        const values = [
          ["Hz", trip.output_frequency_hz], ["A", trip.output_current_a], ["V", trip.output_voltage_v],
        ].filter(([, v]) => v !== null).map(([u, v]) => `${v} ${u}`).join(", ");
        field("at-trip").textContent = values ? `The drive's values at the trip: ${values}.` : "";
      }
      const samples = record.samples;
      const data = [samples.time, ...SERIES.map((s) => samples[s.key] || [])];
      const box = $(main, '[data-testid="trip-chart"]');
      chart = new uPlot({
        width: Math.max(320, box.clientWidth - 2),
        height: 320,
        series: [
          { label: "time" },
          ...SERIES.map((s) => ({ label: s.label, scale: s.scale, stroke: s.stroke, width: 1.5 })),
        ],
        scales: { x: { time: true } },
        axes: [
          {},
          { scale: "Hz", label: "Hz" },
          { scale: "A", label: "A", side: 1, grid: { show: false } },
          { scale: "V", label: "V", side: 1, grid: { show: false } },
        ],
        hooks: { draw: [marker(record.time)] },
      }, data, box);
      window.workbench.tripChart = chart;
      field("samples").textContent = `${samples.time.length} samples, ${record.before_s} s before to ${record.after_s} s after, every ${record.interval_s} s`;
      const body = $(main, '[data-testid="trip-writes"] tbody');
      body.replaceChildren();
      for (const w of record.writes) {
        const row = document.createElement("tr");
        if (w.result !== "ok") row.className = "anomaly";
        cell(row, "time", `${(w.time - record.time).toFixed(1)} s`, "num");
        cell(row, "client", text(w.client));
        cell(row, "what", text(w.what));
        cell(row, "old", text(w.old));
        cell(row, "new", text(w.new));
        cell(row, "result", w.result === "refused" ? w.reason : text(w.result));
        body.appendChild(row);
      }
      field("writes-info").textContent = record.writes.length ? "" : "no write to the drive in the window";
    }
    load().catch((error) => { field("error").textContent = String(error); });
    return {
      kind: "trip",
      update() {},
      close() {
        closed = true;
        if (chart) chart.destroy();
        window.workbench.tripChart = null;
      },
    };
  }

  pages.push(
    { pattern: /^#\/trips$/, page: (main, util) => listPage(main, util) },
    {
      pattern: /^#\/trips\/([^/]+)\/(\d+)$/,
      page: (main, util, m) => listPage(main, util, decodeURIComponent(m[1]), Number(m[2])),
    },
    { pattern: /^#\/trip\/([^/]+)$/, page: (main, util, m) => recordPage(main, util, decodeURIComponent(m[1])) },
  );
})();
