// The REST client of the dashboard: the API key from localStorage, problem+json errors.
// A 401 asks the page (through onUnauthenticated) for a key and retries once it is given.

const KEY_STORE = "fmscell.apiKey";

export class ApiError extends Error {
  constructor(status, problem) {
    super(problem?.detail || problem?.title || `HTTP ${status}`);
    this.status = status;
    this.problem = problem || {};
  }
}

export const auth = {
  get key() {
    return localStorage.getItem(KEY_STORE) || "";
  },
  set key(value) {
    if (value) localStorage.setItem(KEY_STORE, value);
    else localStorage.removeItem(KEY_STORE);
  },
  // Set by the page: returns a promise of a key (or null when the user cancels).
  onUnauthenticated: null,
  declined: false,
};

let pendingKey = null; // one dialog for every request refused at once

async function askForKey(reason) {
  // Once the user dismissed the dialog, refused requests stay refused until they open it
  // themselves: one dialog per dismissal, not one per request still in flight.
  if (!auth.onUnauthenticated || auth.declined) return null;
  if (!pendingKey) {
    pendingKey = auth.onUnauthenticated(reason).then((key) => {
      auth.declined = !key;
      return key;
    }).finally(() => {
      pendingKey = null;
    });
  }
  return pendingKey;
}

/** fetch() on the API: JSON in and out, problem+json turned into ApiError. */
export async function api(path, { method = "GET", json, body, headers = {}, raw = false } = {}) {
  for (let attempt = 0; attempt < 3; attempt++) {
    const h = { Accept: "application/json", ...headers };
    if (auth.key) h["X-API-Key"] = auth.key;
    let payload = body;
    if (json !== undefined) {
      h["Content-Type"] = "application/json";
      payload = JSON.stringify(json);
    }
    const r = await fetch(path, { method, headers: h, body: payload });
    if (r.status === 401) {
      const problem = await readProblem(r);
      const key = await askForKey(problem.detail || "The API asks for a key.");
      if (key) continue;
      throw new ApiError(401, problem);
    }
    if (!r.ok) throw new ApiError(r.status, await readProblem(r));
    if (raw) return r;
    if (r.status === 204) return null;
    const type = r.headers.get("content-type") || "";
    return type.includes("json") ? r.json() : r.text();
  }
  throw new ApiError(401, { detail: "the key was refused" });
}

async function readProblem(r) {
  try {
    const text = await r.text();
    return JSON.parse(text);
  } catch {
    return { status: r.status, detail: `HTTP ${r.status} ${r.statusText}` };
  }
}

/** A page of a cursor-paginated list, or a plain array for lists that are not paginated. */
export function items(page) {
  if (Array.isArray(page)) return page;
  return page?.items || [];
}

/** A UUID for Idempotency-Key; crypto.randomUUID needs a secure context, so fall back. */
export function newKey() {
  if (globalThis.crypto?.randomUUID) {
    try {
      return crypto.randomUUID();
    } catch {
      /* not a secure context (http on a LAN address): fall through */
    }
  }
  const bytes = new Uint8Array(16);
  crypto.getRandomValues(bytes);
  return Array.from(bytes, (b) => b.toString(16).padStart(2, "0")).join("");
}

/** The event stream's URL: EventSource cannot set headers, so the key travels as ?api_key=. */
export function eventsUrl(after) {
  const q = new URLSearchParams();
  if (auth.key) q.set("api_key", auth.key);
  if (after) q.set("after", String(after));
  const s = q.toString();
  return s ? `/api/events?${s}` : "/api/events";
}
