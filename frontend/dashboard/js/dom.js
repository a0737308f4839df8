// Tiny DOM builder: every string becomes a text node, never markup (no innerHTML with server data).

/** el("td", {class: "x", title: t, onclick: f, dataset: {id: 1}}, "text", child, …) */
export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attrs || {})) {
    if (value === undefined || value === null || value === false) continue;
    if (key === "class") node.className = value;
    else if (key === "dataset") Object.assign(node.dataset, value);
    else if (key === "style") Object.assign(node.style, value);
    else if (key.startsWith("on") && typeof value === "function") node.addEventListener(key.slice(2), value);
    else if (key in node && typeof value !== "string") node[key] = value;
    else node.setAttribute(key, value === true ? "" : String(value));
  }
  append(node, children);
  return node;
}

function append(node, children) {
  for (const child of children.flat(Infinity)) {
    if (child === undefined || child === null || child === false) continue;
    node.appendChild(child instanceof Node ? child : document.createTextNode(String(child)));
  }
}

export const $ = (id) => document.getElementById(id);

/** Replace the children of a node (strings as text). */
export function fill(node, ...children) {
  node.replaceChildren();
  append(node, children);
  return node;
}

/** A table from a header list and rows of cells (cells: strings, nodes or {text, class, title}). */
export function table(headers, rows, attrs = {}) {
  const cell = (tag, c) => (c && typeof c === "object" && !(c instanceof Node)
    ? el(tag, { class: c.class, title: c.title }, c.text) : el(tag, {}, c));
  return el("table", attrs,
    el("thead", {}, el("tr", {}, headers.map((h) => cell("th", h)))),
    el("tbody", {}, rows.map((r) => (r instanceof Node ? r : el("tr", {}, r.map((c) => cell("td", c)))))));
}

export function download(name, blob) {
  const a = el("a", { href: URL.createObjectURL(blob), download: name });
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10_000);
}
