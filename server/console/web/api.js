// The server's API as the pages call it: JSON resources under /api, unary calls through the gRPC
// gateway and images, each request carrying the bearer token kept in localStorage. Failures are
// ApiErrors with the server's code and message.

const TOKEN_KEY = 'recog.token';

export function getToken() {
  return localStorage.getItem(TOKEN_KEY) || '';
}

// Keeps `token` for the next requests; an empty one forgets it.
export function setToken(token) {
  if (token) localStorage.setItem(TOKEN_KEY, token);
  else localStorage.removeItem(TOKEN_KEY);
}

// An error answered by the server ({"code","message"}) or met on the way (network, bad JSON).
export class ApiError extends Error {
  constructor(status, code, message) {
    super(message);
    this.status = status;
    this.code = code;
  }
}

async function request(path, { method = 'GET', body, signal } = {}) {
  const headers = {};
  const token = getToken();
  if (token) headers.Authorization = `Bearer ${token}`;
  if (body !== undefined) headers['Content-Type'] = 'application/json';
  let response;
  try {
    response = await fetch(path, {
      method, headers, signal, cache: 'no-store',
      body: body === undefined ? undefined : JSON.stringify(body),
    });
  } catch (err) {
    if (err.name === 'AbortError') throw err;
    throw new ApiError(0, 'UNAVAILABLE', `cannot reach the server (${err.message})`);
  }
  if (!response.ok) {
    let code = `HTTP ${response.status}`;
    let message = response.status === 413 ? 'the request is too large for the server'
      : response.statusText || 'request failed';
    try {
      const data = await response.json();
      if (data.code) code = data.code;
      if (data.message) message = data.message;
    } catch (_) { /* not JSON: keep the HTTP status */ }
    throw new ApiError(response.status, code, message);
  }
  return response;
}

// GET or POST a JSON resource under /api; throws ApiError.
export async function api(path, options = {}) {
  const response = await request(path, options);
  try {
    return await response.json();
  } catch (err) {
    throw new ApiError(response.status, 'INTERNAL', `the server's answer is not JSON (${err.message})`);
  }
}

// One unary call through the gRPC gateway, e.g. rpc('recognition.v1.ObjectRepository', 'ListModels').
export function rpc(service, method, message = {}, signal) {
  return api(`/api/rpc/${service}/${method}`, { method: 'POST', body: message, signal });
}

// An image from the API (sent with the token, which <img src> cannot do). Resolves to
// { image, headers } with a decoded HTMLImageElement, or null when the server has none (404).
export async function apiImage(path, signal) {
  let response;
  try {
    response = await request(path, { signal });
  } catch (err) {
    if (err instanceof ApiError && err.status === 404) return null;
    throw err;
  }
  const url = URL.createObjectURL(await response.blob());
  const image = new Image();
  image.src = url;
  try {
    await image.decode();
  } catch (_) {
    throw new ApiError(response.status, 'INTERNAL', `the image at ${path} cannot be decoded`);
  } finally {
    URL.revokeObjectURL(url);
  }
  return { image, headers: response.headers };
}
