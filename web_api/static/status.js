// The machine status as the tiles read it: pure functions, no DOM (tested under node by
// tests/web_api/test_dashboard_status.py).

// The cell serves each machine's status from its monitoring model (server/host.py:
// MonitoringModel.status, read from the MTConnect agent); a machine's own snapshot
// (cnc.status.MachineStatus as a dict) has other names. The tiles read one view of both.
const CONDITION_SOURCE = { nc_cond: "NC", plc_cond: "PLC", bus_cond: "BUS", dnc_cond: "DNC" };

/** The tiles' view (MachineStatus names) of either status shape; null for no status. */
export function statusView(s) {
  if (!s) return null;
  if (!("actual" in s || "overrides" in s || "connected" in s)) return s; // MachineStatus
  const axes = {};
  for (const ax of new Set([...Object.keys(s.actual || {}), ...Object.keys(s.commanded || {})])) {
    axes[ax] = { actual: s.actual?.[ax], commanded: s.commanded?.[ax] };
  }
  return {
    availability: s.connected === false ? "UNAVAILABLE" : s.availability,
    emergency_stop: s.emergency_stop,
    controller_mode: s.mode,
    mode_detail: s.mode_detail,
    execution: s.execution,
    program: s.program,
    line: s.line,
    block: s.block,
    path_feed_rate: s.feed_mm_min,
    feed_override: s.overrides?.feed,
    rapid_override: s.overrides?.rapid,
    spindle_override: s.overrides?.spindle,
    spindle_speed: s.spindle?.speed_rpm,
    spindle_load: s.spindle?.load_percent,
    axes,
    tool_tip: s.tool_tip
      ? { position: s.tool_tip.position, deviation: s.tool_tip.deviation_mm, peak: s.tool_tip.peak_deviation_mm }
      : null,
    alarms: (s.alarms || []).map((a) => {
      const servo = /^(.*)servo$/.exec(a.condition || "");
      return {
        source: CONDITION_SOURCE[a.condition] || (servo ? "DRIVE" : a.condition || "NC"),
        axis: servo && servo[1] ? servo[1] : null,
        number: a.code,
        text: a.text,
        severity: a.level,
      };
    }),
    part_count: s.counters?.part_count,
    can_bus_load: s.bus_load ? { mean: s.bus_load.mean_percent, peak: s.bus_load.peak_percent } : null,
    plc_scan_time_ms: s.plc?.scan_time_ms,
    unreferenced: s.unreferenced_axes || [],
    cycle_start_refused: s.cycle_start_refused || "",
  };
}

/** [css class, word] of a status view: the tile's colour and the state it writes. */
export function machineState(s) {
  if (!s || s.availability === "UNAVAILABLE") return ["offline", "OFFLINE"];
  const faults = (s.alarms || []).filter((a) => (a.severity || "FAULT") === "FAULT");
  if (s.emergency_stop === "TRIGGERED") return ["alarm", "E-STOP"];
  if (faults.length) return ["alarm", "ALARM"];
  const ex = s.execution || "READY";
  if (ex === "ACTIVE") return ["active", "ACTIVE"];
  if (["FEED_HOLD", "INTERRUPTED", "OPTIONAL_STOP", "PROGRAM_STOPPED"].includes(ex)) return ["hold", ex];
  // reset gives READY without an alarm, but the axes may have lost their reference: the
  // tile says so rather than READY (the cell does not dispatch to it until it is homed)
  if ((s.unreferenced || []).length) return ["warning", "NOT REFERENCED"];
  if ((s.alarms || []).length) return ["warning", ex];
  return ["idle", ex];
}

/** {mean, peak} CAN bus load in percent, or null when the machine does not report it. */
export function busLoad(s) {
  const b = s?.can_bus_load;
  if (b === undefined || b === null) return null;
  if (typeof b === "number") return { mean: b, peak: b };
  if (b.mean === null || b.mean === undefined) return null;
  return { mean: Number(b.mean), peak: b.peak ?? null };
}


/** mill5: the tool tip (forward kinematics, workpiece frame) as plot samples {X, Y, Z};
 * null when the status has none. The tip comes from the interpolated joints: commanded. */
export function tipAxes(tip) {
  const p = tip?.position;
  if (!Array.isArray(p) || p.length !== 3) return null;
  const out = {};
  ["X", "Y", "Z"].forEach((a, i) => {
    out[a] = { actual: p[i], commanded: p[i] };
  });
  return out;
}
