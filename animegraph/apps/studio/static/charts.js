// Bar charts drawn as SVG from the overview's JSON (no plotting library).

const NS = "http://www.w3.org/2000/svg";

function el(name, attrs, text) {
  const node = document.createElementNS(NS, name);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  if (text !== undefined) node.textContent = text;
  return node;
}

// Bars of [label, value] pairs, labels under them, values above.
export function barChart(target, pairs, { width = 640, height = 160, title = "" } = {}) {
  const svg = el("svg", { viewBox: `0 0 ${width} ${height + 34}`, role: "img",
                          "aria-label": title });
  const max = Math.max(1, ...pairs.map(([, v]) => v));
  const step = width / Math.max(1, pairs.length);
  const bar = Math.max(1, step * 0.8);
  pairs.forEach(([label, value], i) => {
    const h = (value / max) * height;
    const x = i * step + (step - bar) / 2;
    const rect = el("rect", { x, y: 12 + height - h, width: bar, height: h });
    rect.append(el("title", {}, `${label}: ${value}`));
    svg.append(rect);
    if (step >= 14) {
      svg.append(el("text", { x: x + bar / 2, y: height + 26, "text-anchor": "middle" }, label));
      svg.append(el("text", { x: x + bar / 2, y: 10 + height - h, "text-anchor": "middle" },
                    String(value)));
    }
  });
  target.replaceChildren(svg);
}

// A histogram of values in `bins` equal bins, labelled by their lower edge.
export function histogram(target, values, { bins = 20, unit = "s", ...options } = {}) {
  if (!values.length) { target.textContent = "no values"; return; }
  const lo = Math.min(...values), hi = Math.max(...values);
  const width = (hi - lo) / bins || 1;
  const counts = new Array(bins).fill(0);
  for (const v of values) counts[Math.min(bins - 1, Math.floor((v - lo) / width))] += 1;
  barChart(target, counts.map((c, i) => [`${(lo + i * width).toFixed(1)}${unit}`, c]), options);
}
