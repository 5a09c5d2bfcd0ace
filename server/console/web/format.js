// How the pages write the server's values: numbers (64-bit ones come as strings), counts, sizes
// in bytes, dates and times, and enum names.

// `value` as a number; 0 when it is not one.
export function num(value) {
  const n = Number(value);
  return Number.isFinite(n) ? n : 0;
}

// 1536 → "1.5 KB", 512 → "512 B".
export function formatBytes(value) {
  let n = num(value);
  const units = ['B', 'KB', 'MB', 'GB', 'TB'];
  let i = 0;
  while (n >= 1024 && i < units.length - 1) { n /= 1024; i += 1; }
  return i === 0 ? `${n} B` : `${n.toFixed(n < 10 ? 1 : 0)} ${units[i]}`;
}

// 12345 → "12,345".
export function formatCount(value) {
  return num(value).toLocaleString('en-US');
}

// Unix milliseconds → "2024-05-01 13:04:05" in local time; "—" for none.
export function formatDate(unixMs) {
  const ms = num(unixMs);
  if (!ms) return '—';
  const d = new Date(ms);
  const pad = (v) => String(v).padStart(2, '0');
  return `${d.getFullYear()}-${pad(d.getMonth() + 1)}-${pad(d.getDate())} ` +
    `${pad(d.getHours())}:${pad(d.getMinutes())}:${pad(d.getSeconds())}`;
}

// Unix milliseconds → "13:04:05".
export function formatTime(unixMs) {
  return formatDate(unixMs).slice(11);
}

// "OBJECT_TYPE_3D" → "3D", "LOOP_STATUS_LOW_SCORE" → "low score".
export function enumName(value, prefix) {
  if (value === undefined || value === null || value === '') return '—';
  let s = String(value);
  if (prefix && s.startsWith(prefix)) s = s.slice(prefix.length);
  return /^[0-9]/.test(s) ? s : s.toLowerCase().replaceAll('_', ' ');
}
