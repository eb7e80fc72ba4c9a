// Live line plots on a 2D canvas: one quantity against simulated time,
// the last few hundred frames, the y axis fitted to what is shown.

/** Points kept per plot: about 20 s of frames at 30 frames/s. */
const KEEP = 600;

function tick(value) {
  if (value === 0) return "0";
  const magnitude = Math.abs(value);
  if (magnitude >= 1e4 || magnitude < 1e-2) return value.toExponential(1);
  return value.toPrecision(3);
}

/** One series against time, with its own scale. */
export class Plot {
  constructor(canvas, { label, unit = "", colour = "#7fb4ff", missing = "not in these frames" }) {
    this.missing = missing;
    this.canvas = canvas;
    this.label = label;
    this.unit = unit;
    this.colour = colour;
    this.times = [];
    this.values = [];
  }

  clear() {
    this.times = [];
    this.values = [];
    this.draw();
  }

  /** Adds a point; a time before the last (a reset) starts the plot over. */
  push(time, value) {
    const last = this.times.length - 1;
    if (last >= 0 && time < this.times[last]) this.clear();
    if (last >= 0 && time === this.times[last]) {
      this.values[last] = value;
    } else {
      this.times.push(time);
      this.values.push(value);
    }
    if (this.times.length > KEEP) {
      this.times.splice(0, this.times.length - KEEP);
      this.values.splice(0, this.values.length - KEEP);
    }
  }

  draw() {
    const canvas = this.canvas;
    const ratio = window.devicePixelRatio || 1;
    canvas.width = Math.round(canvas.clientWidth * ratio);
    canvas.height = Math.round(canvas.clientHeight * ratio);
    const g = canvas.getContext("2d");
    g.setTransform(ratio, 0, 0, ratio, 0, 0);
    const w = canvas.clientWidth;
    const h = canvas.clientHeight;
    g.clearRect(0, 0, w, h);
    g.fillStyle = "#9aa4b2";
    g.font = "11px sans-serif";
    const finite = this.values.filter(Number.isFinite);
    const latest = finite.length ? ` ${tick(finite[finite.length - 1])} ${this.unit}` : ` (${this.missing})`;
    g.fillText(`${this.label}${latest}`, 4, 12);
    if (finite.length < 2) return;
    let lo = Math.min(...finite);
    let hi = Math.max(...finite);
    if (hi - lo < 1e-12 * Math.max(Math.abs(hi), 1)) {
      lo -= 0.5 * Math.max(Math.abs(lo), 1e-12);
      hi += 0.5 * Math.max(Math.abs(hi), 1e-12);
    }
    const t0 = this.times[0];
    const t1 = this.times[this.times.length - 1];
    const left = 44;
    const top = 18;
    const bottom = h - 14;
    const x = (t) => left + ((t - t0) / Math.max(t1 - t0, 1e-12)) * (w - left - 4);
    const y = (v) => bottom - ((v - lo) / (hi - lo)) * (bottom - top);
    g.fillText(tick(hi), 2, top + 8);
    g.fillText(tick(lo), 2, bottom);
    g.fillText(`t ${t0.toFixed(3)} … ${t1.toFixed(3)} s`, left, h - 2);
    g.strokeStyle = "#39404c";
    g.strokeRect(left, top, w - left - 4, bottom - top);
    g.strokeStyle = this.colour;
    g.lineWidth = 1.5;
    g.beginPath();
    let drawing = false;
    for (let i = 0; i < this.times.length; i++) {
      const v = this.values[i];
      if (!Number.isFinite(v)) {
        drawing = false;
        continue;
      }
      if (drawing) g.lineTo(x(this.times[i]), y(v));
      else g.moveTo(x(this.times[i]), y(v));
      drawing = true;
    }
    g.stroke();
  }
}
