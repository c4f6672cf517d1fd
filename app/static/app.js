// squashcal page: sign in, courts, upload and live jobs, result viewer, camera, history.
// Plain JavaScript served by the API itself; no inline script or style (strict CSP).
"use strict";

const $ = (id) => document.getElementById(id);
const KEY_STORE = "squashcal-key";
const COURT_STORE = "squashcal-court";
const STAGES = ["background", "edges", "optimising", "refining", "storing"];
const STAGE_WORDS = {
  queued: "Waiting for a worker",
  background: "Removing the players",
  edges: "Finding the court's lines",
  optimising: "Fitting the camera",
  refining: "Refining the fit",
  storing: "Saving",
  done: "Done",
};
const IMAGE_EXT = ["png", "jpg", "jpeg"];
const VIDEO_EXT = ["mp4", "mov", "mkv", "webm", "avi"];

// plain words for the API's error codes: what was wrong, and what to send or do instead
const ADVICE = {
  unsupported_media_type: "That file is not a photo or video we can read. Send PNG or JPEG photos, or one MP4, MOV, MKV, WebM or AVI clip.",
  upload_too_large: "The upload is too big. A few seconds of video or a handful of photos is enough.",
  mixed_media: "Send either photos or one clip, not both at once.",
  too_many_videos: "Send one clip at a time.",
  too_many_files: "Too many files at once. A handful of photos is enough.",
  too_many_queued_jobs: "You have many calibrations waiting already. Upload again when some have finished.",
  corrupt_image: "A photo could not be read: it may be damaged. Export it again as PNG or JPEG.",
  corrupt_video: "The clip could not be read: it may be damaged or cut short. Export it again as MP4.",
  empty_file: "A file is empty. Pick the file again.",
  video_no_frames: "The clip has no pictures in it. Export it again as MP4.",
  mixed_image_sizes: "The photos have different sizes. Send photos from the same camera at the same size.",
  image_too_large: "A photo is larger than we accept. Send it at normal camera resolution (e.g. 1920 x 1080).",
  video_frame_too_large: "The video is larger than we accept. Send it at 1080p or 4K at most.",
  video_too_long: "The clip is too long. A few seconds of the court is enough.",
  image_too_small: "A photo is too small to find the court's lines in. Send it at normal camera resolution (at least 64 x 48, ideally 1280 x 720 or more).",
  video_frame_too_small: "The video's pictures are too small to find the court's lines in. Send it at 720p or 1080p.",
  too_many_pixels: "The photos are too big together. Send fewer photos (a handful is enough) or smaller ones.",
  no_files: "No file arrived. Pick a clip or photos.",
  media_missing: "The uploaded files went missing on the server. Upload them again.",
  no_static_view: "The clip never holds one view of the court for a second (cuts, zooms or a moving camera). Re-film with the camera fixed, or send a still frame.",
  court_not_found: "We could not find the court's lines. Re-film with the camera still, the whole floor and the front wall in view, the lights on and the lens clean.",
  worker_lost: "The calibration stopped half way on our side. Upload the same footage again.",
  calibration_error: "Something went wrong on our side while calibrating. Try again; if it keeps failing, tell your service operator.",
  internal_error: "Something went wrong on our side while calibrating. Try again; if it keeps failing, tell your service operator.",
  database_error: "Our database was briefly unavailable. The calibration is retried by itself.",
  storage_error: "Our storage failed while calibrating. The calibration is retried by itself.",
  out_of_memory: "The calibration ran out of memory on our side. Try fewer or smaller photos.",
  invalid_input: "The footage could not be used. Send a clip or photos of a squash court.",
  unauthorized: "The API key was not accepted. Check it, or ask for a new one.",
};

const state = {
  key: localStorage.getItem(KEY_STORE) || "",
  config: null,
  courts: [],
  courtId: null,
  calibrations: [],
  viewing: null, // the calibration shown
  lines: null,
  busy: false,
  jobs: new Map(), // job id -> card
};

// ------------------------------------------------------------------------------------------
// API

class ApiError extends Error {
  constructor(status, code, message) {
    super(message);
    this.status = status;
    this.code = code;
  }
}

// requests and image decodes in flight: the page says it is busy until they are all done, so
// that screen readers (and the browser tests, before a reload) can tell when it has settled
let pendingWork = 0;

async function busyWith(promise) {
  pendingWork += 1;
  document.body.setAttribute("aria-busy", "true");
  try {
    return await promise;
  } finally {
    pendingWork -= 1;
    if (pendingWork === 0) document.body.setAttribute("aria-busy", "false");
  }
}

const UNAVAILABLE_RETRIES = 3;

// how long to wait before sending again a request answered 503: the service's Retry-After
// (a header value), within 10 s
async function waitBeforeRetry(retryAfter) {
  const waitS = Math.min(Number(retryAfter) || 2, 10);
  await new Promise((resolve) => setTimeout(resolve, 1000 * waitS));
}

function api(path, options = {}) {
  return busyWith(request(path, options));
}

async function request(path, options) {
  const headers = { Authorization: `Bearer ${state.key}` };
  let body = options.body;
  if (options.json !== undefined) {
    headers["Content-Type"] = "application/json";
    body = JSON.stringify(options.json);
  }
  let response;
  for (let attempt = 0; ; attempt += 1) {
    try {
      response = await fetch(path, { method: options.method || "GET", headers, body });
    } catch (e) {
      throw new ApiError(0, "network", "The service cannot be reached. Check your connection and try again.");
    }
    // 503 means the service did nothing (its database was busy or down for a moment): the
    // same request is safe to send again after the wait the service asks for
    if (response.status !== 503 || attempt >= UNAVAILABLE_RETRIES) break;
    await waitBeforeRetry(response.headers.get("Retry-After"));
  }
  if (!response.ok) throw await errorOf(response);
  const type = response.headers.get("content-type") || "";
  if (options.raw) return response;
  return type.includes("json") ? response.json() : response.blob();
}

async function errorOf(response) {
  let code = "http_error";
  let message = `${response.status} ${response.statusText}`;
  try {
    const body = await response.json();
    if (body && body.error) ({ code, message } = body.error);
  } catch (e) { /* not JSON */ }
  return new ApiError(response.status, code, message);
}

// the line search finds the camera; the paper's GA runs only when an upload names a bundle
function howFound(cal) {
  return cal.generations ? `GA, seed ${cal.seed}, ${cal.generations} generations` : "found from the court's lines";
}

function explain(error) {
  const advice = ADVICE[error.code];
  return advice ? `${advice}\n(${error.message})` : error.message || String(error);
}

async function bitmap(path) {
  return busyWith(api(path).then((blob) => createImageBitmap(blob)));
}

// ------------------------------------------------------------------------------------------
// small helpers

function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") node.className = v;
    else if (k === "text") node.textContent = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else if (v !== false && v !== null && v !== undefined) node.setAttribute(k, v === true ? "" : v);
  }
  for (const child of children) if (child !== null && child !== undefined) node.append(child);
  return node;
}

const SVG_NS = "http://www.w3.org/2000/svg";
function svg(tag, attrs = {}) {
  const node = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  return node;
}

const fmt = (v, digits = 2) => (v === null || v === undefined || !Number.isFinite(v) ? "–" : v.toFixed(digits));
const seconds = (s) => (s < 60 ? `${Math.round(s)} s` : `${Math.floor(s / 60)} min ${Math.round(s % 60)} s`);
const when = (iso) => new Date(iso).toLocaleString([], { dateStyle: "medium", timeStyle: "short" });
const extOf = (name) => (name.includes(".") ? name.split(".").pop().toLowerCase() : "");
const mb = (bytes) => `${(bytes / 1048576).toFixed(bytes < 10485760 ? 1 : 0)} MB`;

function download(blob, name) {
  const url = URL.createObjectURL(blob);
  const a = el("a", { href: url, download: name });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}

function setError(id, error) {
  $(id).textContent = error ? (error instanceof ApiError ? explain(error) : String(error.message || error)) : "";
}

// ------------------------------------------------------------------------------------------
// sign in

async function signIn(key) {
  state.key = key;
  setError("key-error", null);
  let me;
  try {
    me = await api("/me");
  } catch (e) {
    setError("key-error", e);
    showSignedIn(false);
    return;
  }
  localStorage.setItem(KEY_STORE, key);
  $("who-text").textContent = `Signed in as ${me.key_name || "?"}${me.tenant_name && me.tenant_name !== me.key_name ? ` (${me.tenant_name})` : ""}.`;
  showSignedIn(true);
  await loadCourts(localStorage.getItem(COURT_STORE));
}

function showSignedIn(yes) {
  $("sign-in").hidden = yes;
  $("who").hidden = !yes;
  $("app").hidden = !yes;
}

// ------------------------------------------------------------------------------------------
// courts

async function loadCourts(selectId) {
  const { courts } = await api("/courts");
  state.courts = courts;
  const select = $("courts");
  select.replaceChildren(
    ...courts.map((c) => el("option", { value: c.id, text: `${c.name} (${specName(c.spec)})${c.active_calibration_id ? "" : " – not calibrated yet"}` })),
  );
  if (!courts.length) {
    select.append(el("option", { value: "", text: "No court yet: create one below" }));
    $("new-court-box").open = true;
  }
  const wanted = courts.find((c) => c.id === selectId) ? selectId : courts.length ? courts[courts.length - 1].id : "";
  select.value = wanted;
  await selectCourt(wanted || null);
}

function specName(spec) {
  const found = (state.config?.specs || []).find((s) => s.name === spec);
  return found ? found.description.replace("WSF ", "") : spec;
}

async function selectCourt(courtId) {
  state.courtId = courtId;
  if (courtId) localStorage.setItem(COURT_STORE, courtId);
  state.viewing = null;
  $("result").hidden = true;
  $("camera-panel").hidden = true;
  $("history-panel").hidden = !courtId;
  for (const [id, card] of state.jobs) if (card.courtId !== courtId) { card.stop(); state.jobs.delete(id); }
  $("jobs").replaceChildren(...[...state.jobs.values()].map((c) => c.node));
  if (!courtId) return;
  await loadHistory();
  const active = state.calibrations.find((c) => c.active) || state.calibrations[0];
  if (active) await showCalibration(active);
  // jobs still running (e.g. after a reload), and recent failures, get their cards back
  const { jobs } = await api(`/courts/${courtId}/jobs?limit=5`);
  const newest = state.calibrations[0]?.created_at || "";
  for (const job of jobs.reverse()) {
    if (state.jobs.has(job.id)) continue;
    if (job.status === "queued" || job.status === "running" || (job.status === "failed" && job.created_at > newest)) {
      trackJob(job.id, job.media_kind === "video" ? "clip" : `${job.n_files} photo(s)`, job);
    }
  }
}

async function createCourt(event) {
  event.preventDefault();
  setError("court-error", null);
  const button = $("create-court");
  button.disabled = true;
  try {
    const court = await api("/courts", { method: "POST", json: { name: $("court-name").value.trim(), spec: $("court-spec").value } });
    $("court-name").value = "";
    $("new-court-box").open = false;
    await loadCourts(court.id);
  } catch (e) {
    setError("court-error", e);
  } finally {
    button.disabled = false;
  }
}

// ------------------------------------------------------------------------------------------
// upload

function checkFiles(files) {
  if (!files.length) return "Pick a clip or some photos first.";
  const kinds = files.map((f) => {
    const ext = extOf(f.name);
    if (IMAGE_EXT.includes(ext) || f.type === "image/png" || f.type === "image/jpeg") return "image";
    if (VIDEO_EXT.includes(ext) || f.type.startsWith("video/")) return "video";
    return null;
  });
  const bad = files.filter((_, i) => kinds[i] === null);
  if (bad.length) return `${bad.map((f) => `"${f.name}"`).join(", ")} is not a photo or clip we can read. Send PNG or JPEG photos, or one MP4, MOV, MKV, WebM or AVI clip.`;
  const videos = kinds.filter((k) => k === "video").length;
  if (videos && videos < files.length) return "Send either photos or one clip, not both at once.";
  if (videos > 1) return "Send one clip at a time.";
  const empty = files.find((f) => f.size === 0);
  if (empty) return `"${empty.name}" is empty. Pick the file again.`;
  const limits = state.config;
  if (limits && files.length > limits.max_files) return `That is ${files.length} files; send at most ${limits.max_files} photos.`;
  const total = files.reduce((s, f) => s + f.size, 0);
  if (limits && total > limits.max_upload_bytes) return `That is ${mb(total)}; the limit is ${mb(limits.max_upload_bytes)}. A few seconds of video is enough: trim the clip or send fewer photos.`;
  return null;
}

function setBusy(busy) {
  state.busy = busy;
  $("demo").disabled = busy;
  $("files").disabled = busy;
  $("drop").classList.toggle("busy", busy);
}

// the upload is sent again after a 503 (the service stored nothing: its database was busy),
// as every other request is; the files are still in hand, so it costs only the wait
async function uploadWithProgress(courtId, files) {
  for (let attempt = 0; ; attempt += 1) {
    try {
      return await sendUpload(courtId, files);
    } catch (e) {
      if (!(e instanceof ApiError) || e.status !== 503 || attempt >= UNAVAILABLE_RETRIES) throw e;
      $("upload-label").textContent = "The service is busy for a moment; sending again";
      await waitBeforeRetry(e.retryAfter);
    }
  }
}

function sendUpload(courtId, files) {
  return new Promise((resolve, reject) => {
    const form = new FormData();
    for (const f of files) form.append("files", f, f.name);
    const xhr = new XMLHttpRequest();
    xhr.open("POST", `/courts/${courtId}/calibrations`);
    xhr.setRequestHeader("Authorization", `Bearer ${state.key}`);
    xhr.upload.onprogress = (e) => {
      if (e.lengthComputable) {
        $("upload-progress").value = e.loaded / e.total;
        $("upload-label").textContent = `Uploading: ${mb(e.loaded)} of ${mb(e.total)}`;
      }
    };
    xhr.upload.onload = () => { $("upload-label").textContent = "Checking the files"; };
    xhr.onerror = () => reject(new ApiError(0, "network", "The upload was interrupted. Check your connection and try again."));
    xhr.onload = () => {
      let body = null;
      try { body = JSON.parse(xhr.responseText); } catch (e) { /* not JSON */ }
      if (xhr.status === 202 && body) resolve(body);
      else {
        const error = new ApiError(xhr.status, body?.error?.code || "http_error", body?.error?.message || `${xhr.status} ${xhr.statusText}`);
        error.retryAfter = xhr.getResponseHeader("Retry-After");
        reject(error);
      }
    };
    xhr.send(form);
  });
}

async function upload(files, label) {
  if (state.busy) return;
  setError("upload-error", null);
  if (!state.courtId) { setError("upload-error", "Create or choose a court first."); return; }
  const problem = checkFiles(files);
  if (problem) { setError("upload-error", problem); return; }
  setBusy(true);
  $("upload-status").hidden = false;
  $("upload-progress").value = 0;
  $("upload-label").textContent = "Uploading";
  try {
    const accepted = await uploadWithProgress(state.courtId, files);
    trackJob(accepted.job_id, label || (files.length === 1 ? files[0].name : `${files.length} photos`));
  } catch (e) {
    setError("upload-error", e);
  } finally {
    setBusy(false);
    $("upload-status").hidden = true;
    $("files").value = "";
  }
}

async function demo() {
  if (state.busy) return;
  setError("upload-error", null);
  setBusy(true);
  $("upload-status").hidden = false;
  $("upload-progress").removeAttribute("value");
  $("upload-label").textContent = "Making a demo clip of a rendered court (a few seconds)";
  let file;
  try {
    if (!state.courtId) {
      const court = await api("/courts", { method: "POST", json: { name: "Demo court", spec: "wsf" } });
      await loadCourts(court.id);
    }
    const blob = await api("/demo/clip.mp4");
    file = new File([blob], "squashcal-demo.mp4", { type: "video/mp4" });
  } catch (e) {
    setError("upload-error", e);
    setBusy(false);
    $("upload-status").hidden = true;
    return;
  }
  setBusy(false);
  await upload([file], "demo clip (rendered court)");
}

// ------------------------------------------------------------------------------------------
// live job cards

function trackJob(jobId, label, initial) {
  const card = new JobCard(jobId, label, state.courtId);
  state.jobs.set(jobId, card);
  $("jobs").prepend(card.node);
  card.start(initial);
}

class JobCard {
  constructor(jobId, label, courtId) {
    this.id = jobId;
    this.courtId = courtId;
    this.series = []; // [generation, best fitness]
    this.startedAt = performance.now();
    this.timer = null;
    this.stages = el("ol", { class: "stages", "aria-label": "Stages" }, ...STAGES.map((s) => el("li", { text: STAGE_WORDS[s] })));
    this.bar = el("progress", { max: "1", value: "0", "aria-label": "Calibration progress" });
    this.status = el("p", { class: "line", role: "status" });
    this.timing = el("p", { class: "line hint" });
    this.plot = el("canvas", { width: "420", height: "70", "aria-label": "Best fitness per generation", hidden: true });
    this.extra = el("div");
    this.node = el("li", { class: "job" }, el("h3", { text: `Calibrating ${label}` }), this.stages, this.bar, this.status, this.timing, this.plot, this.extra);
  }

  start(initial) {
    if (initial) this.update(initial);
    if (!initial || initial.status === "queued" || initial.status === "running") this.poll();
  }

  stop() { clearTimeout(this.timer); this.timer = null; this.stopped = true; }

  async poll() {
    if (this.stopped) return;
    let job;
    try {
      job = await api(`/jobs/${this.id}`);
    } catch (e) {
      this.status.textContent = `Could not read the job: ${explain(e)}`;
      this.timer = setTimeout(() => this.poll(), 2000);
      return;
    }
    await this.update(job);
    if (job.status === "queued" || job.status === "running") this.timer = setTimeout(() => this.poll(), 500);
  }

  async update(job) {
    const node = this.node;
    node.classList.toggle("succeeded", job.status === "succeeded");
    node.classList.toggle("failed", job.status === "failed");
    // running, but its worker stopped renewing the lease (killed, or cut off): say so
    node.classList.toggle("stale", job.status === "running" && job.stale);
    const index = STAGES.indexOf(job.stage);
    const failed = job.status === "failed";
    this.stages.querySelectorAll("li").forEach((li, i) => {
      // a failed job's stage is "done": what it got through shows in its stage times
      const done = job.status === "succeeded" || (failed ? STAGES[i] in job.timings_s : i < index);
      li.className = done ? "done" : i === index && !failed ? "now" : "";
    });
    if (failed && !this.stages.querySelector(".failed")) this.stages.append(el("li", { class: "failed", text: "Failed" }));
    // while the start position is searched no figure moves: the bar says "working" instead
    const searching = job.status === "running" && job.stage === "optimising" && !job.generation;
    if (searching) this.bar.removeAttribute("value");
    else this.bar.value = job.progress;
    this.node.dataset.progress = job.progress;
    const started = job.started_at ? Date.parse(job.started_at) : null;
    const end = job.finished_at ? Date.parse(job.finished_at) : Date.now();
    const elapsed = started ? Math.max(0, (end - started) / 1000) : 0;
    if (job.status === "queued") {
      this.status.textContent = job.attempts ? "Waiting for a worker to take it up again" : STAGE_WORDS.queued;
      this.timing.textContent = "";
    } else if (job.status === "running" && job.stale) {
      this.status.textContent = job.attempts < job.max_attempts
        ? "The worker stopped responding: the job will be retried by another worker"
        : "The worker stopped responding, and the job has used all its attempts: it will be marked failed";
      const quiet = job.heartbeat_at ? Math.max(0, (Date.now() - Date.parse(job.heartbeat_at)) / 1000) : null;
      this.timing.textContent = quiet !== null ? `no sign of it for ${seconds(quiet)} (attempt ${job.attempts} of ${job.max_attempts})` : "";
    } else if (job.status === "running") {
      let words = STAGE_WORDS[job.stage] || job.stage;
      if (job.stage === "optimising") {
        if (job.generation) {
          words += `: generation ${job.generation}`;
          if (job.best_fitness !== null) words += `, best fitness ${fmt(job.best_fitness, 1)}`;
          const last = this.series[this.series.length - 1];
          if (!last || last[0] !== job.generation) this.series.push([job.generation, job.best_fitness]);
        } else {
          words += ": looking for a starting position of the camera";
        }
      }
      this.status.textContent = words;
      const p = job.progress;
      const left = p > 0.15 && p < 1 ? (elapsed * (1 - p)) / p : null;
      this.timing.textContent = `${seconds(elapsed)} so far${left !== null ? ` · about ${seconds(left)} left` : " · estimating the time left"}`;
      this.drawPlot();
    } else if (job.status === "succeeded") {
      this.status.textContent = "Done: the camera is calibrated.";
      this.timing.textContent = `took ${seconds(elapsed)}`;
      this.drawPlot();
      if (!this.finished) {
        this.finished = true;
        this.extra.replaceChildren(el("button", { type: "button", class: "secondary", text: "Show this result", onclick: () => this.showResult(job) }));
        if (this.courtId === state.courtId) await this.showResult(job);
      }
    } else if (job.status === "failed") {
      this.status.textContent = "Failed: no camera was made from this footage.";
      this.timing.textContent = started ? `stopped after ${seconds(elapsed)}` : "";
      const err = job.error || { code: "calibration_error", message: "" };
      this.extra.replaceChildren(
        el("p", { class: "line advice", text: ADVICE[err.code] || "The calibration failed." }),
        el("p", { class: "line hint", text: `Details: ${err.code}: ${err.message}` }),
      );
    }
  }

  async showResult(job) {
    await loadHistory();
    const cal = state.calibrations.find((c) => c.id === job.calibration_id);
    if (cal) await showCalibration(cal);
    await refreshCourtNames();
  }

  drawPlot() {
    if (this.series.length < 2) return;
    this.plot.hidden = false;
    const ctx = this.plot.getContext("2d");
    const { width, height } = this.plot;
    ctx.clearRect(0, 0, width, height);
    const xs = this.series.map((p) => p[0]);
    const ys = this.series.map((p) => p[1]).filter(Number.isFinite);
    const x0 = Math.min(...xs), x1 = Math.max(...xs, x0 + 1);
    const y0 = Math.min(...ys), y1 = Math.max(...ys, y0 + 1e-9);
    ctx.strokeStyle = "#1565c0";
    ctx.lineWidth = 2;
    ctx.beginPath();
    this.series.forEach(([x, y], i) => {
      const u = 4 + ((x - x0) / (x1 - x0)) * (width - 8);
      const v = height - 14 - ((y - y0) / (y1 - y0)) * (height - 22);
      if (i) ctx.lineTo(u, v); else ctx.moveTo(u, v);
    });
    ctx.stroke();
    ctx.fillStyle = "#5f6b73";
    ctx.font = "11px system-ui, sans-serif";
    ctx.fillText(`best fitness over generations ${x0}–${x1}`, 4, height - 2);
  }
}

async function refreshCourtNames() {
  const current = state.courtId;
  const { courts } = await api("/courts");
  state.courts = courts;
  for (const option of $("courts").options) {
    const c = courts.find((x) => x.id === option.value);
    if (c) option.textContent = `${c.name} (${specName(c.spec)})${c.active_calibration_id ? "" : " – not calibrated yet"}`;
  }
  $("courts").value = current;
}

// ------------------------------------------------------------------------------------------
// history

// Several loads can be in flight (a job finishing, "Make active"): answers may come back out of
// order, and an older one must not paint over a newer one (a stale "Active" badge).
let historyRequests = 0;

async function loadHistory() {
  if (!state.courtId) return;
  const ticket = ++historyRequests;
  const { calibrations } = await api(`/courts/${state.courtId}/calibrations`);
  if (ticket !== historyRequests) return;
  state.calibrations = calibrations;
  $("history-panel").hidden = false;
  const list = $("history");
  list.replaceChildren(...calibrations.map(historyItem));
  if (!calibrations.length) list.append(el("li", { class: "hint", text: "No calibration yet: upload a clip above, or try it without footage." }));
}

function verdictOf(cal) {
  if (cal.source === "import") return { label: "imported", words: "Imported camera" };
  if (!cal.verdict) return { label: "unknown", words: "No verdict: check the overlay" };
  if (cal.verdict.label === "good") return { label: "good", words: "Good" };
  return { label: "check", words: "Check the overlay" };
}

function historyItem(cal) {
  const thumb = el("canvas", { width: "240", height: "135", "aria-label": `Overlay of calibration from ${when(cal.created_at)}` });
  drawThumb(thumb, cal);
  const verdict = verdictOf(cal);
  const viewButton = el("button", { type: "button", class: "secondary", text: "View", onclick: () => showCalibration(cal) });
  const activeButton = cal.active
    ? null
    : el("button", { type: "button", text: "Make active", onclick: (e) => makeActive(cal, e.currentTarget) });
  return el(
    "li",
    { class: state.viewing?.id === cal.id ? "viewing" : "", "data-id": cal.id },
    thumb,
    el("div", {}, cal.active ? el("span", { class: "badge active", text: "Active" }) : null, el("span", { class: `badge ${verdict.label}`, text: verdict.words })),
    el("div", { class: "meta", text: `${when(cal.created_at)} · ${cal.source === "import" ? "imported" : howFound(cal)}` }),
    el("div", { class: "actions" }, viewButton, activeButton),
  );
}

async function drawThumb(canvas, cal) {
  try {
    const image = await bitmap(`/calibrations/${cal.id}/overlay.png?width=240`);
    canvas.height = Math.round((240 * image.height) / image.width);
    canvas.getContext("2d").drawImage(image, 0, 0, canvas.width, canvas.height);
  } catch (e) { /* the card still says what it is */ }
}

async function makeActive(cal, button) {
  button.disabled = true;
  try {
    await api(`/courts/${state.courtId}/camera`, { method: "POST", json: { calibration_id: cal.id } });
    await loadHistory();
    await refreshCourtNames();
    const now = state.calibrations.find((c) => c.id === (state.viewing?.id || cal.id));
    if (now) await showCalibration(now);
  } catch (e) {
    button.disabled = false;
    setError("import-error", e);
  }
}

async function importCamera(event) {
  event.preventDefault();
  setError("import-error", null);
  let text = $("import-text").value.trim();
  const file = $("import-file").files[0];
  if (!text && file) text = await file.text();
  let cameraJson;
  try {
    cameraJson = JSON.parse(text);
  } catch (e) {
    setError("import-error", "That is not valid JSON. Paste the camera as {\"K\": ..., \"dist\": ..., \"rvec\": ..., \"tvec\": ..., \"image_size\": [w, h]}.");
    return;
  }
  try {
    const cal = await api(`/courts/${state.courtId}/calibrations/import`, { method: "POST", json: { camera: cameraJson } });
    $("import-text").value = "";
    $("import-file").value = "";
    await loadHistory();
    await refreshCourtNames();
    await showCalibration(state.calibrations.find((c) => c.id === cal.id) || cal);
  } catch (e) {
    setError("import-error", e);
  }
}

// ------------------------------------------------------------------------------------------
// result: verdict, viewer, diagram, camera panel

async function showCalibration(cal) {
  state.viewing = cal;
  $("result").hidden = false;
  $("camera-panel").hidden = false;
  for (const li of $("history").children) li.classList.toggle("viewing", li.dataset.id === cal.id);
  showVerdict(cal);
  showCamera(cal);
  viewer.clearMarks();
  diagram.clearMark();
  $("readout").textContent = "Click the picture or the diagram.";
  const lines = await api(`/calibrations/${cal.id}/lines`);
  if (state.viewing !== cal) return;
  state.lines = lines;
  $("show-start").disabled = !lines.start;
  if (!lines.start) $("show-start").checked = false;
  $("show-edges").disabled = cal.source === "import";
  diagram.draw(lines);
  await viewer.load(cal, lines);
  $("convergence-box").hidden = cal.source === "import";
  if ($("convergence-box").open) drawConvergence();
}

function showVerdict(cal) {
  const box = $("verdict");
  const v = verdictOf(cal);
  const reasons = cal.verdict?.reasons || [];
  const floor = cal.uncertainty?.floor_error_cm;
  let title, detail;
  if (v.label === "good") {
    title = "Good: the court lines match the picture.";
    detail = floor && Number.isFinite(floor.T) ? `Floor positions are good to about ${fmt(floor.T, 1)} cm at the T.` : "You can use this camera.";
  } else if (v.label === "check") {
    title = "Check the overlay before you use this camera.";
    detail = "Look whether the green lines sit on the court's painted lines and wall edges.";
  } else if (v.label === "imported") {
    title = "Imported camera.";
    detail = "It was not checked against footage of this court.";
  } else {
    title = "Check the overlay: this calibration carries no automatic verdict.";
    detail = "If the green lines sit on the court's lines and wall edges, the camera is good.";
  }
  box.className = `verdict ${v.label === "imported" ? "unknown" : v.label}`;
  box.replaceChildren(el("strong", { text: title }), el("span", { text: detail }));
  if (reasons.length) box.append(el("ul", {}, ...reasons.map((r) => el("li", { text: r }))));
  const figures = { ...(cal.verdict?.figures || {}) };
  if (cal.verdict && Number.isFinite(cal.verdict.score)) figures["verdict score"] = cal.verdict.score;
  if (floor) for (const [k, val] of Object.entries(floor)) figures[`floor error at ${k.replace("_", " ")} (cm)`] = val;
  for (const [k, val] of Object.entries(cal.uncertainty?.parameters || {})) figures[`std of ${k}`] = val;
  for (const [k, val] of Object.entries(cal.quality || {})) figures[k.replaceAll("_", " ")] = val;
  if (cal.fitness !== null) figures.fitness = cal.fitness;
  $("figures").replaceChildren(...Object.entries(figures).map(([k, val]) => el("tr", {}, el("th", { text: k }), el("td", { text: typeof val === "number" ? fmt(val, Math.abs(val) < 10 ? 3 : 1) : JSON.stringify(val) }))));
  $("figures-box").hidden = !Object.keys(figures).length;
}

function showCamera(cal) {
  const K = cal.opencv.K;
  const d = cal.opencv.dist;
  const p = cal.pose;
  const rows = [
    ["Image size", `${cal.opencv.image_size[0]} × ${cal.opencv.image_size[1]} px`],
    ["Focal length", `${fmt(K[0][0], 1)} px across, ${fmt(K[1][1], 1)} px down`],
    ["Principal point", `${fmt(K[0][2], 1)}, ${fmt(K[1][2], 1)} px`],
    ["Lens distortion", `k1 ${fmt(d[0], 4)}, k2 ${fmt(d[1], 4)}, k3 ${fmt(d[4], 4)}, p1 ${fmt(d[2], 5)}, p2 ${fmt(d[3], 5)}`],
    ["Camera position", `x ${fmt(p.position_m[0])} m, y ${fmt(p.position_m[1])} m (court frame)`],
    ["Camera height", `${fmt(p.height_m)} m above the floor`],
    ["Looking", `pan ${fmt(p.pan_deg, 1)}° (0 = at the front wall, + = to the right), tilt ${fmt(p.tilt_deg, 1)}° down, roll ${fmt(p.roll_deg, 1)}°`],
    ["Field of view", `${fmt(p.fov_deg[0], 1)}° × ${fmt(p.fov_deg[1], 1)}°`],
    ["rvec / tvec", `${cal.opencv.rvec.map((v) => fmt(v, 4)).join(", ")} / ${cal.opencv.tvec.map((v) => fmt(v, 3)).join(", ")}`],
    ["Made", `${when(cal.created_at)}${cal.source === "import" ? " (imported)" : `, ${howFound(cal)}`}`],
    ["Calibration id", cal.id],
  ];
  $("camera-table").replaceChildren(...rows.map(([k, v]) => el("tr", {}, el("th", { text: k }), el("td", { text: v }))));
}

async function drawConvergence() {
  const cal = state.viewing;
  if (!cal || cal.source === "import") return;
  const canvas = $("convergence");
  if (canvas.dataset.id === cal.id) return;
  const image = await bitmap(`/calibrations/${cal.id}/convergence.png`);
  canvas.width = image.width;
  canvas.height = image.height;
  canvas.getContext("2d").drawImage(image, 0, 0);
  canvas.dataset.id = cal.id;
}

// the picture: background, line evidence and court lines on a canvas, with zoom and pan
const viewer = {
  canvas: null,
  background: null,
  edges: null,
  size: [1, 1],
  scale: 1, tx: 0, ty: 0,
  marks: [],

  init() {
    this.canvas = $("viewer");
    const c = this.canvas;
    let drag = null;
    c.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, y: e.clientY, tx: this.tx, ty: this.ty, moved: false }; c.setPointerCapture(e.pointerId); });
    c.addEventListener("pointermove", (e) => {
      if (!drag) return;
      const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      if (Math.hypot(dx, dy) > 4) drag.moved = true;
      if (drag.moved) { this.tx = drag.tx + dx * this.ratio(); this.ty = drag.ty + dy * this.ratio(); this.clamp(); this.draw(); }
    });
    c.addEventListener("pointerup", (e) => {
      if (drag && !drag.moved) this.clicked(e);
      drag = null;
    });
    c.addEventListener("wheel", (e) => {
      e.preventDefault();
      const [px, py] = this.canvasPoint(e);
      this.zoomAt(px, py, e.deltaY < 0 ? 1.25 : 0.8);
    }, { passive: false });
    c.addEventListener("keydown", (e) => {
      const step = 40 * this.ratio();
      const moves = { ArrowLeft: [step, 0], ArrowRight: [-step, 0], ArrowUp: [0, step], ArrowDown: [0, -step] };
      if (moves[e.key]) { this.tx += moves[e.key][0]; this.ty += moves[e.key][1]; this.clamp(); this.draw(); e.preventDefault(); }
      else if (e.key === "+" || e.key === "=") { this.zoomAt(c.width / 2, c.height / 2, 1.25); e.preventDefault(); }
      else if (e.key === "-") { this.zoomAt(c.width / 2, c.height / 2, 0.8); e.preventDefault(); }
      else if (e.key === "0") { this.fit(); e.preventDefault(); }
    });
    $("zoom-in").addEventListener("click", () => this.zoomAt(c.width / 2, c.height / 2, 1.25));
    $("zoom-out").addEventListener("click", () => this.zoomAt(c.width / 2, c.height / 2, 0.8));
    $("zoom-fit").addEventListener("click", () => this.fit());
    for (const id of ["show-fitted", "show-start", "show-edges"]) $(id).addEventListener("change", () => this.draw());
    new ResizeObserver(() => this.resize()).observe(c.parentElement);
  },

  ratio() { return this.canvas.width / Math.max(1, this.canvas.clientWidth); },

  canvasPoint(e) {
    const r = this.canvas.getBoundingClientRect();
    return [(e.clientX - r.left) * this.ratio(), (e.clientY - r.top) * this.ratio()];
  },

  // image pixel (OpenCV: centre of the top-left pixel at 0,0) <-> canvas pixel
  toCanvas(u, v) { return [(u + 0.5) * this.scale + this.tx, (v + 0.5) * this.scale + this.ty]; },
  toImage(x, y) { return [(x - this.tx) / this.scale - 0.5, (y - this.ty) / this.scale - 0.5]; },

  async load(cal, lines) {
    this.size = lines.image_size;
    this.background = null;
    this.edges = null;
    this.resize();
    if (cal.source === "import") { this.draw(); return; }
    const [background, edges] = await Promise.all([
      bitmap(`/calibrations/${cal.id}/background.png`),
      bitmap(`/calibrations/${cal.id}/edges.png`),
    ]);
    if (state.viewing !== cal) return;
    this.background = background;
    this.edges = edges;
    this.draw();
  },

  resize() {
    const c = this.canvas;
    const dpr = window.devicePixelRatio || 1;
    const width = Math.max(1, Math.round(c.parentElement.clientWidth * dpr));
    const height = Math.round((width * this.size[1]) / this.size[0]);
    if (c.width !== width || c.height !== height) {
      c.width = width;
      c.height = height;
      this.fit();
    }
  },

  fit() {
    this.scale = this.canvas.width / this.size[0];
    this.tx = 0;
    this.ty = 0;
    this.draw();
  },

  zoomAt(x, y, factor) {
    const min = this.canvas.width / this.size[0];
    const scale = Math.min(Math.max(this.scale * factor, min), min * 16);
    const f = scale / this.scale;
    this.tx = x - (x - this.tx) * f;
    this.ty = y - (y - this.ty) * f;
    this.scale = scale;
    this.clamp();
    this.draw();
  },

  clamp() {
    const w = this.size[0] * this.scale, h = this.size[1] * this.scale;
    this.tx = Math.min(0, Math.max(this.canvas.width - w, this.tx));
    this.ty = Math.min(0, Math.max(this.canvas.height - h, this.ty));
  },

  draw() {
    const c = this.canvas;
    const ctx = c.getContext("2d");
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = "#303030";
    ctx.fillRect(0, 0, c.width, c.height);
    ctx.imageSmoothingEnabled = this.scale < 2;
    const w = this.size[0] * this.scale, h = this.size[1] * this.scale;
    const edgesOn = $("show-edges").checked && this.edges;
    if (this.background) {
      ctx.globalAlpha = edgesOn ? 0.35 : 1;
      ctx.drawImage(this.background, this.tx, this.ty, w, h);
      ctx.globalAlpha = 1;
    }
    if (edgesOn) {
      ctx.globalCompositeOperation = "lighter";
      ctx.drawImage(this.edges, this.tx, this.ty, w, h);
      ctx.globalCompositeOperation = "source-over";
    }
    const lines = state.lines;
    const px = window.devicePixelRatio || 1;
    if (lines && lines.start && $("show-start").checked) this.polylines(ctx, lines.start, "#ff9800", 2 * px, [6 * px, 4 * px]);
    if (lines && $("show-fitted").checked) this.polylines(ctx, lines.fitted, "#43e047", 2 * px, []);
    for (const mark of this.marks) this.mark(ctx, mark, px);
  },

  polylines(ctx, polylines, colour, width, dash) {
    for (const [stroke, lineWidth] of [["rgba(0,0,0,0.75)", width + 2], [colour, width]]) {
      ctx.strokeStyle = stroke;
      ctx.lineWidth = lineWidth;
      ctx.setLineDash(dash);
      ctx.lineJoin = "round";
      ctx.beginPath();
      for (const line of polylines) {
        line.forEach(([u, v], i) => {
          const [x, y] = this.toCanvas(u, v);
          if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y);
        });
      }
      ctx.stroke();
    }
    ctx.setLineDash([]);
  },

  mark(ctx, { u, v, colour }, px) {
    const [x, y] = this.toCanvas(u, v);
    const r = 7 * px;
    for (const [stroke, lw] of [["#000", 4 * px], [colour, 2 * px]]) {
      ctx.strokeStyle = stroke;
      ctx.lineWidth = lw;
      ctx.beginPath();
      ctx.arc(x, y, r, 0, 2 * Math.PI);
      ctx.moveTo(x - 2 * r, y); ctx.lineTo(x - r, y);
      ctx.moveTo(x + r, y); ctx.lineTo(x + 2 * r, y);
      ctx.moveTo(x, y - 2 * r); ctx.lineTo(x, y - r);
      ctx.moveTo(x, y + r); ctx.lineTo(x, y + 2 * r);
      ctx.stroke();
    }
  },

  setMark(u, v, colour) {
    this.marks = [{ u, v, colour }];
    this.draw();
  },

  clearMarks() { this.marks = []; if (this.canvas) this.draw(); },

  async clicked(e) {
    if (!state.viewing) return;
    const [x, y] = this.canvasPoint(e);
    const [u, v] = this.toImage(x, y);
    if (u < -0.5 || v < -0.5 || u > this.size[0] - 0.5 || v > this.size[1] - 0.5) return;
    await measurePixel(u, v);
  },
};

async function measurePixel(u, v) {
  const cal = state.viewing;
  viewer.setMark(u, v, "#ffeb3b");
  const body = await api(`/calibrations/${cal.id}/project`, { method: "POST", json: { pixels: [[u, v]] } });
  const point = body.points[0];
  const where = `pixel (${fmt(u, 1)}, ${fmt(v, 1)})`;
  if (!point) {
    diagram.clearMark();
    $("readout").textContent = `${where}: this point is not on the floor (above the horizon or outside the lens's range).`;
    return;
  }
  diagram.setMark(point[0], point[1]);
  $("readout").textContent = `Floor position: x ${fmt(point[0])} m, y ${fmt(point[1])} m${body.inside_court[0] ? "" : " (outside the court)"}, at ${where}`;
  $("readout").dataset.x = point[0];
  $("readout").dataset.y = point[1];
}

async function measureFloor(x, y) {
  const cal = state.viewing;
  diagram.setMark(x, y);
  const body = await api(`/calibrations/${cal.id}/image-points`, { method: "POST", json: { points: [[x, y]] } });
  const pixel = body.pixels[0];
  if (!pixel) {
    viewer.clearMarks();
    $("readout").textContent = `Floor (${fmt(x)} m, ${fmt(y)} m) is behind the camera.`;
    return;
  }
  viewer.setMark(pixel[0], pixel[1], "#ffeb3b");
  $("readout").textContent = `Floor (${fmt(x)} m, ${fmt(y)} m) is at pixel (${fmt(pixel[0], 1)}, ${fmt(pixel[1], 1)})${body.in_image[0] ? "" : ", outside the picture"}`;
  $("readout").dataset.u = pixel[0];
  $("readout").dataset.v = pixel[1];
}

// the court from above, in metres: SVG with x right, y down (front wall at the top)
const diagram = {
  node: null,
  marker: null,

  init() {
    this.node = $("diagram");
    this.node.addEventListener("click", (e) => {
      if (!state.viewing || !state.lines) return;
      const point = this.node.createSVGPoint();
      point.x = e.clientX;
      point.y = e.clientY;
      const m = point.matrixTransform(this.node.getScreenCTM().inverse());
      measureFloor(m.x, m.y);
    });
  },

  draw(lines) {
    const [w, l] = lines.court_m;
    const pad = 0.7;
    const s = this.node;
    s.setAttribute("viewBox", `${-pad} ${-pad} ${w + 2 * pad} ${l + 2 * pad}`);
    s.replaceChildren(
      svg("rect", { x: -pad, y: -pad, width: w + 2 * pad, height: l + 2 * pad, fill: "#fff" }),
      svg("rect", { x: 0, y: 0, width: w, height: l, fill: "#e9cfa8" }),
    );
    const seg = ([a, b], colour, width) => svg("line", { x1: a[0], y1: a[1], x2: b[0], y2: b[1], stroke: colour, "stroke-width": width, "stroke-linecap": "square" });
    for (const segment of lines.floor.painted) s.append(seg(segment, "#c62828", 0.05));
    for (const segment of lines.floor.outline) s.append(seg(segment, "#263238", 0.08));
    const label = (text, x, y) => {
      const t = svg("text", { x, y, "text-anchor": "middle", "font-size": 0.32, fill: "#5f6b73" });
      t.textContent = text;
      return t;
    };
    s.append(label("FRONT WALL", w / 2, -0.22), label("BACK WALL", w / 2, l + 0.45));
    this.marker = svg("g", { visibility: "hidden" });
    this.marker.append(
      svg("circle", { r: 0.16, fill: "#ffeb3b", stroke: "#000", "stroke-width": 0.05 }),
      svg("circle", { r: 0.03, fill: "#000" }),
    );
    s.append(this.marker);
  },

  setMark(x, y) {
    if (!this.marker) return;
    this.marker.setAttribute("transform", `translate(${x} ${y})`);
    this.marker.setAttribute("visibility", "visible");
  },

  clearMark() { if (this.marker) this.marker.setAttribute("visibility", "hidden"); },
};

// ------------------------------------------------------------------------------------------
// wiring

function wire() {
  $("key").value = state.key;
  $("key-form").addEventListener("submit", (e) => { e.preventDefault(); signIn($("key").value.trim()); });
  $("sign-out").addEventListener("click", () => {
    localStorage.removeItem(KEY_STORE);
    state.key = "";
    $("key").value = "";
    for (const card of state.jobs.values()) card.stop();
    state.jobs.clear();
    $("jobs").replaceChildren();
    showSignedIn(false);
    $("key").focus();
  });
  $("courts").addEventListener("change", () => selectCourt($("courts").value || null).catch((e) => setError("court-error", e)));
  $("court-form").addEventListener("submit", createCourt);
  $("files").addEventListener("change", () => upload([...$("files").files]));
  const drop = $("drop");
  drop.addEventListener("dragover", (e) => { e.preventDefault(); drop.classList.add("over"); });
  drop.addEventListener("dragleave", () => drop.classList.remove("over"));
  drop.addEventListener("drop", (e) => {
    e.preventDefault();
    drop.classList.remove("over");
    upload([...(e.dataTransfer?.files || [])]);
  });
  // a file dropped next to the zone must not navigate away from the page
  window.addEventListener("dragover", (e) => e.preventDefault());
  window.addEventListener("drop", (e) => e.preventDefault());
  $("demo").addEventListener("click", demo);
  $("download-json").addEventListener("click", () => {
    const cal = state.viewing;
    download(new Blob([JSON.stringify(cal.opencv, null, 2) + "\n"], { type: "application/json" }), `camera-${cal.id.slice(0, 8)}.json`);
  });
  $("download-yaml").addEventListener("click", async () => {
    const cal = state.viewing;
    download(await api(`/calibrations/${cal.id}/camera.yaml`), `camera-${cal.id.slice(0, 8)}.yaml`);
  });
  $("convergence-box").addEventListener("toggle", () => { if ($("convergence-box").open) drawConvergence(); });
  $("import-form").addEventListener("submit", importCamera);
  $("pixel-form").addEventListener("submit", (e) => { e.preventDefault(); measurePixel(Number($("pixel-u").value), Number($("pixel-v").value)); });
  $("floor-form").addEventListener("submit", (e) => { e.preventDefault(); measureFloor(Number($("floor-x").value), Number($("floor-y").value)); });
  viewer.init();
  diagram.init();
}

async function main() {
  wire();
  try {
    state.config = await (await fetch("/ui/config")).json();
    $("court-spec").replaceChildren(...state.config.specs.map((s) => el("option", { value: s.name, text: s.description })));
  } catch (e) { /* checks fall back to the server's */ }
  if (state.key) await signIn(state.key);
  else showSignedIn(false);
}

window.addEventListener("unhandledrejection", (e) => {
  // an action that failed says so where the user looks too (the console still shows it)
  const target = $("app").hidden ? "key-error" : "upload-error";
  setError(target, e.reason);
});

main();
