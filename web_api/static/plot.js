// A live 2D toolpath plot on <canvas>: commanded against actual, in machine coordinates.
// No library: a ring of recent points per trace, an auto-fitted equal-aspect view.

const MAX_POINTS = 3000;

export class ToolpathPlot {
  /** @param canvas the element; @param axes [horizontal, vertical] axis names */
  constructor(canvas, axes) {
    this.canvas = canvas;
    this.axes = axes;
    this.cmd = [];
    this.act = [];
    this.canvas.dataset.points = "0";
  }

  /** Adds one status sample ({axis: {actual, commanded}}); ignores samples without the axes. */
  push(axisStatus) {
    const [h, v] = this.axes;
    const a = axisStatus?.[h];
    const b = axisStatus?.[v];
    if (!a || !b) return;
    const known = (v) => v !== null && v !== undefined && v !== "" && Number.isFinite(Number(v));
    if (![a.actual, a.commanded, b.actual, b.commanded].every(known)) return; // UNAVAILABLE
    const add = (trace, p) => {
      const last = trace[trace.length - 1];
      if (last && last[0] === p[0] && last[1] === p[1]) return; // standing still
      trace.push(p);
      if (trace.length > MAX_POINTS) trace.splice(0, trace.length - MAX_POINTS);
    };
    add(this.cmd, [num(a.commanded), num(b.commanded)]);
    add(this.act, [num(a.actual), num(b.actual)]);
    this.canvas.dataset.points = String(this.act.length);
  }

  clear() {
    this.cmd = [];
    this.act = [];
    this.canvas.dataset.points = "0";
  }

  draw() {
    const c = this.canvas;
    const ctx = c.getContext("2d");
    if (!ctx) return;
    const w = c.width;
    const hgt = c.height;
    const style = getComputedStyle(c);
    ctx.clearRect(0, 0, w, hgt);
    ctx.fillStyle = style.getPropertyValue("--plot-bg") || "#fff";
    ctx.fillRect(0, 0, w, hgt);
    const all = this.cmd.concat(this.act);
    if (all.length === 0) {
      ctx.fillStyle = style.getPropertyValue("--plot-fg") || "#333";
      ctx.font = "12px sans-serif";
      ctx.fillText("no motion yet", 10, 20);
      return;
    }
    let [x0, y0, x1, y1] = [Infinity, Infinity, -Infinity, -Infinity];
    for (const [x, y] of all) {
      x0 = Math.min(x0, x);
      x1 = Math.max(x1, x);
      y0 = Math.min(y0, y);
      y1 = Math.max(y1, y);
    }
    const pad = 14;
    const span = Math.max(x1 - x0, y1 - y0, 1); // at least 1 mm: a still tool is a dot
    const scale = Math.min((w - 2 * pad) / span, (hgt - 2 * pad) / span);
    const cx = (x0 + x1) / 2;
    const cy = (y0 + y1) / 2;
    const px = (x) => w / 2 + (x - cx) * scale;
    const py = (y) => hgt / 2 - (y - cy) * scale; // machine +Y is up

    this.#grid(ctx, style, w, hgt, scale, px, py, x0, x1, y0, y1);
    // Actual first, commanded dashed on top: where they coincide both stay visible.
    this.#trace(ctx, this.act, style.getPropertyValue("--plot-act") || "#c2410c", [], 2.2, px, py);
    this.#trace(ctx, this.cmd, style.getPropertyValue("--plot-cmd") || "#1f5fbf", [5, 4], 1.4, px, py);
    const last = this.act[this.act.length - 1];
    if (last) {
      ctx.fillStyle = style.getPropertyValue("--plot-act") || "#c2410c";
      ctx.beginPath();
      ctx.arc(px(last[0]), py(last[1]), 3.5, 0, 2 * Math.PI);
      ctx.fill();
    }
    ctx.fillStyle = style.getPropertyValue("--plot-fg") || "#333";
    ctx.font = "11px sans-serif";
    ctx.fillText(`${this.axes[0]} →`, w - 34, hgt - 4);
    ctx.fillText(`${this.axes[1]} ↑`, 4, 12);
  }

  #grid(ctx, style, w, hgt, scale, px, py, x0, x1, y0, y1) {
    // Grid lines at a round step (1, 2, 5 × 10^n mm) about 40 px apart.
    const raw = 40 / scale;
    const mag = 10 ** Math.floor(Math.log10(raw));
    const step = [1, 2, 5, 10].map((k) => k * mag).find((s) => s >= raw) || raw;
    ctx.strokeStyle = style.getPropertyValue("--plot-grid") || "#ddd";
    ctx.lineWidth = 1;
    ctx.setLineDash([]);
    ctx.beginPath();
    const spanX = (w / scale) / 2;
    const spanY = (hgt / scale) / 2;
    const mx = (x0 + x1) / 2;
    const my = (y0 + y1) / 2;
    for (let x = Math.floor((mx - spanX) / step) * step; x <= mx + spanX; x += step) {
      ctx.moveTo(px(x), 0);
      ctx.lineTo(px(x), hgt);
    }
    for (let y = Math.floor((my - spanY) / step) * step; y <= my + spanY; y += step) {
      ctx.moveTo(0, py(y));
      ctx.lineTo(w, py(y));
    }
    ctx.stroke();
    ctx.fillStyle = style.getPropertyValue("--plot-fg") || "#333";
    ctx.font = "10px sans-serif";
    ctx.fillText(`grid ${fmtStep(step)} mm`, 4, hgt - 4);
  }

  #trace(ctx, pts, color, dash, width, px, py) {
    if (pts.length < 1) return;
    ctx.strokeStyle = color;
    ctx.lineWidth = width;
    ctx.setLineDash(dash);
    ctx.beginPath();
    ctx.moveTo(px(pts[0][0]), py(pts[0][1]));
    for (const [x, y] of pts) ctx.lineTo(px(x), py(y));
    ctx.stroke();
    ctx.setLineDash([]);
  }
}

function num(v) {
  const n = Number(v);
  return Number.isFinite(n) ? n : 0;
}

function fmtStep(s) {
  return s >= 1 ? String(Math.round(s)) : s.toPrecision(1);
}

/** The plotted plane of a machine: a lathe plots Z across and X up, a mill X across, Y up. */
export function planeOf(kind, axisNames) {
  if (kind === "lathe" && axisNames.includes("Z") && axisNames.includes("X")) return ["Z", "X"];
  if (axisNames.includes("X") && axisNames.includes("Y")) return ["X", "Y"];
  return axisNames.slice(0, 2);
}
