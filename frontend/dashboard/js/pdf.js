// A one-page PDF report (ISO 32000-1) holding a JPEG picture and a title line: objects, a content
// stream, a cross-reference table with byte offsets. No library: the picture carries the content.

const PAGE_PT = [842, 595];  // A4 landscape
const MARGIN_PT = 28;
const TITLE_PT = 12;

const ascii = (text) => text.replace(/[^\x20-\x7e]/g, "?").replace(/[\\()]/g, (c) => `\\${c}`);

/** PDF bytes: `title` on top, the JPEG (widthPx × heightPx) scaled to fit the rest of the page. */
export function pdfWithJpeg(jpeg, widthPx, heightPx, title) {
  const [pw, ph] = PAGE_PT;
  const room = [pw - 2 * MARGIN_PT, ph - 2 * MARGIN_PT - 2 * TITLE_PT];
  const scale = Math.min(room[0] / widthPx, room[1] / heightPx);
  const [w, h] = [widthPx * scale, heightPx * scale];
  const content = `BT /F1 ${TITLE_PT} Tf ${MARGIN_PT} ${ph - MARGIN_PT - TITLE_PT} Td (${ascii(title)}) Tj ET\n`
    + `q ${w.toFixed(2)} 0 0 ${h.toFixed(2)} ${MARGIN_PT} ${(ph - MARGIN_PT - 2 * TITLE_PT - h).toFixed(2)} cm /Im1 Do Q\n`;
  const objects = [
    "<< /Type /Catalog /Pages 2 0 R >>",
    "<< /Type /Pages /Kids [3 0 R] /Count 1 >>",
    `<< /Type /Page /Parent 2 0 R /MediaBox [0 0 ${pw} ${ph}] /Resources << /Font << /F1 6 0 R >> /XObject << /Im1 4 0 R >> >> /Contents 5 0 R >>`,
    [`<< /Type /XObject /Subtype /Image /Width ${widthPx} /Height ${heightPx} /ColorSpace /DeviceRGB /BitsPerComponent 8 /Filter /DCTDecode /Length ${jpeg.length} >>\nstream\n`, jpeg, "\nendstream"],
    [`<< /Length ${content.length} >>\nstream\n${content}endstream`],
    "<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica >>",
    `<< /Title (${ascii(title)}) /Producer (acs-twin dashboard) >>`,
  ];
  const encoder = new TextEncoder();
  const parts = [];
  let length = 0;
  const push = (chunk) => {
    const bytes = typeof chunk === "string" ? encoder.encode(chunk) : chunk;
    parts.push(bytes);
    length += bytes.length;
  };
  push("%PDF-1.4\n%\xe2\xe3\xcf\xd3\n");
  const offsets = [];
  objects.forEach((body, i) => {
    offsets.push(length);
    push(`${i + 1} 0 obj\n`);
    for (const chunk of [].concat(body)) push(chunk);
    push("\nendobj\n");
  });
  const xref = length;
  push(`xref\n0 ${objects.length + 1}\n0000000000 65535 f \n`);
  for (const offset of offsets) push(`${String(offset).padStart(10, "0")} 00000 n \n`);
  push(`trailer\n<< /Size ${objects.length + 1} /Root 1 0 R /Info 7 0 R >>\nstartxref\n${xref}\n%%EOF\n`);
  return new Blob(parts, { type: "application/pdf" });
}

/** PDF report of a canvas (drawn as a JPEG on white-free dark background as it is on screen). */
export async function pdfOfCanvas(canvas, title) {
  const blob = await new Promise((resolve) => canvas.toBlob(resolve, "image/jpeg", 0.92));
  const jpeg = new Uint8Array(await blob.arrayBuffer());
  return pdfWithJpeg(jpeg, canvas.width, canvas.height, title);
}
