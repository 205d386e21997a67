/* app.js: the page side of the plastinet web demo (examples/web, `make web`). demo.js (emscripten,
   -sMODULARIZE, factory createPlastinetDemo) holds the simulation (demo.c); this file steps it once
   per animation frame, draws the particles into an ImageData, and drives the collider with the
   pointer (mouse, pen or touch). window.demo exposes the state to tests/web_test.py. */
'use strict';

window.startPlastinetDemo = function (M) {
  const canvas = document.getElementById('view');
  const ctx = canvas.getContext('2d');
  const statsEl = document.getElementById('stats');
  const W = canvas.width, H = canvas.height;
  const BUDGET_MS = 22;          /* simulation work per frame; beyond it the demo runs slower than real time */
  const MAX_FRAME_S = 1 / 30;    /* simulated time per frame at most */

  let kind = 0;                  /* 0 sand, 1 snow */
  let n = 0;
  const boxW = M._demo_info(0), boxH = M._demo_info(1), floorY = M._demo_info(2), radius = M._demo_info(5);
  const scale = W / boxW;        /* px per m */
  /* particles are drawn as round dots a little wider than their spacing (dx / 2 = 1/64 m), so
     material at rest looks solid and loose material looks grainy */
  const dot = Math.max(3, Math.round(scale / 64) + 2);
  const span = [];               /* per row of a dot: first column and width (corners cut) */
  for (let yy = 0; yy < dot; ++yy) {
    const cut = dot >= 5 && (yy === 0 || yy === dot - 1) ? (dot >= 7 ? 2 : 1) : dot >= 7 && (yy === 1 || yy === dot - 2) ? 1 : 0;
    span.push([cut, dot - 2 * cut]);
  }

  /* ---- colours (ImageData words are little-endian ABGR) ---- */
  const rgba = (r, g, b) => (255 << 24 | b << 16 | g << 8 | r) >>> 0;
  const palettes = [
    { rest: [224, 186, 118], fast: [96, 178, 255], jitter: 16 },   /* sand */
    { rest: [233, 239, 247], fast: [92, 170, 255], jitter: 7 }      /* snow */
  ];
  let grain = new Float32Array(0);   /* per-particle shade in [-1, 1], fixed: a grain texture */

  /* background: a dark gradient inside the box, the walls around it (the floor a little lighter) */
  const bg = new Uint32Array(W * H);
  (function paintBackground() {
    const wallPx = Math.round(floorY * scale);
    for (let y = 0; y < H; ++y) {
      const t = y / H;
      const inside = rgba(24 + 12 * t | 0, 31 + 14 * t | 0, 43 + 16 * t | 0);
      for (let x = 0; x < W; ++x) {
        let c = inside;
        const wall = x < wallPx || x >= W - wallPx || y < wallPx;
        if (y >= H - wallPx) c = y === H - wallPx ? rgba(118, 128, 142) : rgba(44, 50, 60);
        else if (wall) c = (x === wallPx - 1 || x === W - wallPx || y === wallPx - 1) ? rgba(58, 68, 84) : rgba(17, 22, 30);
        bg[y * W + x] = c;
      }
    }
  })();
  const image = ctx.createImageData(W, H);
  const pixels = new Uint32Array(image.data.buffer);

  function reset(k) {
    if (k !== undefined) kind = k;
    n = M._demo_reset(kind);
    if (n <= 0) throw new Error('demo_reset failed (' + n + ')');
    grain = new Float32Array(n);
    let s = 12345;
    for (let i = 0; i < n; ++i) {   /* a fixed pseudo-random shade per particle */
      s = (s * 1103515245 + 12345) >>> 0;
      grain[i] = ((s >>> 8) & 1023) / 511.5 - 1;
    }
    document.getElementById('sand').setAttribute('aria-pressed', String(kind === 0));
    document.getElementById('snow').setAttribute('aria-pressed', String(kind === 1));
  }

  /* ---- pointer: the collider follows it while pressed inside the box ---- */
  const pointer = { down: false, over: false, x: 0, y: 0, touched: false };
  function toWorld(e) {
    const r = canvas.getBoundingClientRect();
    const u = (e.clientX - r.left) / r.width, v = (e.clientY - r.top) / r.height;
    pointer.over = u >= 0 && u <= 1 && v >= 0 && v <= 1;
    pointer.x = u * boxW;
    pointer.y = (1 - v) * boxH;
  }
  canvas.addEventListener('pointerdown', e => {
    canvas.setPointerCapture(e.pointerId);
    pointer.down = true;
    pointer.touched = true;
    toWorld(e);
    e.preventDefault();
  });
  canvas.addEventListener('pointermove', e => toWorld(e));
  const release = e => {
    pointer.down = false;
    if (e.pointerType !== 'mouse') pointer.over = false;   /* a lifted finger leaves no hover */
  };
  canvas.addEventListener('pointerup', release);
  canvas.addEventListener('pointercancel', release);
  canvas.addEventListener('pointerleave', () => { if (!pointer.down) pointer.over = false; });

  document.getElementById('reset').addEventListener('click', () => reset());
  document.getElementById('sand').addEventListener('click', () => reset(0));
  document.getElementById('snow').addEventListener('click', () => reset(1));
  window.addEventListener('keydown', e => { if (e.key === 'r' || e.key === 'R') reset(); });

  /* ---- drawing ---- */
  function particles() {
    const at = M._demo_particles() >> 2;   /* fetch HEAPF32 each time: memory growth replaces it */
    return M.HEAPF32.subarray(at, at + 3 * n);
  }
  function draw(p) {
    pixels.set(bg);
    const pal = palettes[kind], rest = pal.rest, fast = pal.fast, jit = pal.jitter;
    const half = dot >> 1;
    for (let i = 0; i < n; ++i) {
      const sp = p[3 * i + 2];
      if (sp < 0) continue;   /* retired */
      const x0 = Math.round(p[3 * i] * scale) - half, y0 = Math.round(H - p[3 * i + 1] * scale) - half;
      if (x0 < 0 || y0 < 0 || x0 + dot > W || y0 + dot > H) continue;
      const t = Math.sqrt(Math.min(1, sp / 1.5)), g = grain[i] * jit * (1 - t);
      const r = rest[0] + (fast[0] - rest[0]) * t + g, gg = rest[1] + (fast[1] - rest[1]) * t + g,
        b = rest[2] + (fast[2] - rest[2]) * t + g * 0.8;
      const c = rgba(Math.max(0, Math.min(255, r)) | 0, Math.max(0, Math.min(255, gg)) | 0,
        Math.max(0, Math.min(255, b)) | 0);
      for (let yy = 0; yy < dot; ++yy) {
        const at = (y0 + yy) * W + x0 + span[yy][0];
        pixels.fill(c, at, at + span[yy][1]);
      }
    }
    ctx.putImageData(image, 0, 0);
    /* the collider while pressed; a dashed outline where it would appear while hovering */
    const cx = M._demo_info(3), cy = M._demo_info(4);
    if (cy < boxH + radius) {
      ctx.beginPath();
      ctx.arc(cx * scale, H - cy * scale, radius * scale, 0, 2 * Math.PI);
      ctx.fillStyle = 'rgba(210, 225, 245, 0.16)';
      ctx.fill();
      ctx.lineWidth = 2;
      ctx.strokeStyle = 'rgba(235, 242, 252, 0.9)';
      ctx.stroke();
    } else if (pointer.over && !pointer.down) {
      ctx.beginPath();
      ctx.arc(pointer.x * scale, H - pointer.y * scale, radius * scale, 0, 2 * Math.PI);
      ctx.setLineDash([5, 6]);
      ctx.lineWidth = 1.5;
      ctx.strokeStyle = 'rgba(235, 242, 252, 0.45)';
      ctx.stroke();
      ctx.setLineDash([]);
    }
    if (!pointer.touched) {
      ctx.font = '15px system-ui, sans-serif';
      ctx.textAlign = 'center';
      ctx.fillStyle = 'rgba(217, 225, 234, 0.55)';
      ctx.fillText('drag in the box to push the ' + (kind ? 'snow' : 'sand'), W / 2, 60);
    }
  }

  /* ---- the loop ---- */
  const stats = { frames: 0, failures: 0, simMs: NaN, drawMs: NaN, frameMs: NaN, speed: NaN, substeps: 0,
    costMsPerSimS: 0, shownAt: 0 };
  const ema = (old, x, a) => (Number.isFinite(old) ? old + a * (x - old) : x);
  let last = 0;
  function tick(now) {
    requestAnimationFrame(tick);
    const elapsed = last ? Math.min(0.25, (now - last) / 1000) : 1 / 60;
    last = now;
    /* real time when the work fits the budget, else slower */
    let simS = Math.min(Math.max(elapsed, 1 / 240), MAX_FRAME_S);
    if (stats.costMsPerSimS > 0) simS = Math.min(simS, BUDGET_MS / stats.costMsPerSimS);
    simS = Math.max(simS, 1 / 1000);
    M._demo_pointer(pointer.down && pointer.over ? 1 : 0, pointer.x, pointer.y);
    const t0 = performance.now();
    const steps = M._demo_frame(simS);
    const t1 = performance.now();
    if (steps < 0) {
      stats.failures++;
      console.warn('plastinet demo: a step failed even at a smaller step; resetting');
      reset();
    }
    draw(particles());
    const t2 = performance.now();
    stats.frames++;
    stats.substeps = steps;
    stats.simMs = ema(stats.simMs, t1 - t0, 0.1);
    stats.drawMs = ema(stats.drawMs, t2 - t1, 0.1);
    stats.frameMs = ema(stats.frameMs, elapsed * 1000, 0.1);
    stats.speed = ema(stats.speed, simS / elapsed, 0.1);
    stats.costMsPerSimS = ema(stats.costMsPerSimS || NaN, (t1 - t0) / simS, 0.2);
    if (now - stats.shownAt > 250) {
      stats.shownAt = now;
      statsEl.innerHTML = 'sim <b>' + stats.simMs.toFixed(1) + ' ms</b> (' + steps + ' steps) &middot; draw <b>' +
        stats.drawMs.toFixed(1) + ' ms</b> &middot; <b>' + M._demo_info(11) + '</b> particles &middot; ' +
        (1000 / stats.frameMs).toFixed(0) + ' fps &middot; ' + stats.speed.toFixed(2) + '&times; real time';
    }
    if (stats.frames === 10) document.documentElement.dataset.running = 'true';
  }

  reset(0);
  /* for tests and the console */
  window.demo = {
    get frames() { return stats.frames; },
    get simMs() { return stats.simMs; },
    get drawMs() { return stats.drawMs; },
    get particles() { return M._demo_info(11); },
    get maxSpeed() { return M._demo_info(6); },
    get failures() { return stats.failures; },          /* frames whose step failed (then reset) */
    get retried() { return M._demo_info(12); },         /* steps that failed and were retried halved */
    get kind() { return kind; },
    get collider() { return [M._demo_info(3), M._demo_info(4), radius]; },
    box: [boxW, boxH, floorY],
    positions() {   /* [x0, y0, x1, y1, ...] in m; NaN for retired particles */
      const p = particles(), out = new Array(2 * n);
      for (let i = 0; i < n; ++i) {
        out[2 * i] = p[3 * i + 2] < 0 ? NaN : p[3 * i];
        out[2 * i + 1] = p[3 * i + 2] < 0 ? NaN : p[3 * i + 1];
      }
      return out;
    },
    toClient(x, y) {   /* a point of the box (m) in CSS pixels of the viewport */
      const r = canvas.getBoundingClientRect();
      return [r.left + x / boxW * r.width, r.top + (1 - y / boxH) * r.height];
    },
    reset
  };
  requestAnimationFrame(tick);
};
