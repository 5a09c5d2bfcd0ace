// Draws two frames side by side with one line per inlier pair: used by a map's loop list (frame ↔
// the frame it closes a loop with) and by "Try it" (query image ↔ the recognised frame). A side
// whose image is missing is a grey box of the frame's aspect saying "no image kept"; its points are
// drawn all the same.

const GAP = 10;  // pixels between the two sides

// canvas: the <canvas> to draw into (resized here).
// left, right: { image: HTMLImageElement | null, width, height } — width and height are the
//   frame's full resolution, the space the pair coordinates are in.
// pairs: [[lx, ly, rx, ry], ...] in full-resolution pixels of left and right.
// height: the drawn height of both sides in CSS pixels (default: the left image's own height,
//   at most 320).
export function drawPairs(canvas, left, right, pairs, { height } = {}) {
  const L = size(left);
  const R = size(right);
  const h = Math.round(height || Math.min(320, (left.image && left.image.naturalHeight) || L.height));
  const scaleL = h / L.height;
  const scaleR = h / R.height;
  const wL = Math.round(L.width * scaleL);
  const wR = Math.round(R.width * scaleR);
  const width = wL + GAP + wR;

  const dpr = window.devicePixelRatio || 1;
  canvas.width = Math.round(width * dpr);
  canvas.height = Math.round(h * dpr);
  canvas.style.width = `${width}px`;
  const ctx = canvas.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, width, h);

  drawSide(ctx, left.image, 0, wL, h);
  drawSide(ctx, right.image, wL + GAP, wR, h);

  const xR = wL + GAP;
  ctx.lineWidth = 1.2;
  pairs.forEach(([lx, ly, rx, ry], i) => {
    const colour = `hsl(${(i * 47) % 360}, 85%, 50%)`;
    const a = [lx * scaleL, ly * scaleL];
    const b = [xR + rx * scaleR, ry * scaleR];
    ctx.strokeStyle = colour;
    ctx.globalAlpha = 0.75;
    ctx.beginPath();
    ctx.moveTo(a[0], a[1]);
    ctx.lineTo(b[0], b[1]);
    ctx.stroke();
    ctx.globalAlpha = 1;
    ctx.fillStyle = colour;
    for (const [x, y] of [a, b]) {
      ctx.beginPath();
      ctx.arc(x, y, 2.5, 0, 2 * Math.PI);
      ctx.fill();
    }
  });
}

// The full-resolution size of a side: as given, else its image's, else a 4:3 box.
function size(side) {
  const image = side.image;
  const width = side.width || (image && image.naturalWidth) || 320;
  const height = side.height || (image && image.naturalHeight) || Math.round(width * 3 / 4);
  return { width, height };
}

function drawSide(ctx, image, x, w, h) {
  if (image) {
    ctx.drawImage(image, x, 0, w, h);
    return;
  }
  ctx.fillStyle = '#d5d8dc';
  ctx.fillRect(x, 0, w, h);
  ctx.fillStyle = '#5f6670';
  ctx.font = '14px system-ui, sans-serif';
  ctx.textAlign = 'center';
  ctx.textBaseline = 'middle';
  ctx.fillText('no image kept', x + w / 2, h / 2);
}
