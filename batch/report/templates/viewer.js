/* report.html's float image viewer (issue 21). Vanilla JS, no build step, no network: every
   view is drawn from linear half floats that a script file beside the render defines (script
   tags load from file://, fetch does not), inflated with the browser's DecompressionStream.

   Data file: spectralBench.data(document.currentScript, {w, h, layers: {NAME: {channels: [..],
   data: bytes}}}): each layer's values are IEEE 754 binary16, channel after channel, row-major
   from the top-left pixel, their low bytes then their high bytes, zlib-deflated, the bytes as the
   characters of a string that the file's charset x-user-defined gives them (WHATWG Encoding
   Standard; batch/report/html.py writes them). Half floats carry 11 significant bits (relative
   rounding 2^-11 = 4.9e-4).

   Formulas: sRGB transfer function IEC 61966-2-1; Stokes degree of polarisation
   sqrt(S1^2 + S2^2 + S3^2) / S0 and angle 0.5 atan2(S2, S1) (Goldstein, Polarized Light, 3rd ed.,
   ch. 4), in the scenes' Stokes frame (docs/scenes.md; 0 horizontal, counter-clockwise as seen from the camera). */
var spectralBench = (function () {
  'use strict';
  var HALF = new Float32Array(65536);
  (function () {
    for (var i = 0; i < 65536; i++) {
      var s = i & 0x8000 ? -1 : 1, e = (i >> 10) & 31, m = i & 1023;
      HALF[i] = e === 0 ? s * m * Math.pow(2, -24) : e === 31 ? (m ? NaN : s * Infinity)
        : s * (1 + m / 1024) * Math.pow(2, e - 15);
    }
  })();
  // colour maps as tables of control points (matplotlib's viridis and magma sampled at tenths,
  // a blue-white-red diverging map), interpolated linearly
  var MAPS = {
    viridis: ['440154', '482878', '3e4989', '31688e', '26828e', '1f9e89', '35b779', '6ece58', 'b5de2b', 'fde725'],
    magma: ['000004', '180f3d', '440f76', '721f81', '9e2f7f', 'cd4071', 'f1605d', 'fd9668', 'feca8d', 'fcfdbf'],
    diverging: ['2166ac', '4393c3', '92c5de', 'd1e5f0', 'f7f7f7', 'fddbc7', 'f4a582', 'd6604d', 'b2182b'],
    cyclic: ['ff0000', 'ffff00', '00ff00', '00ffff', '0000ff', 'ff00ff', 'ff0000']
  };
  var LUT = {};
  Object.keys(MAPS).forEach(function (k) {
    var pts = MAPS[k].map(function (h) { return [parseInt(h.slice(0, 2), 16), parseInt(h.slice(2, 4), 16), parseInt(h.slice(4), 16)]; });
    var t = new Uint8ClampedArray(256 * 3);
    for (var i = 0; i < 256; i++) {
      var x = i / 255 * (pts.length - 1), j = Math.min(Math.floor(x), pts.length - 2), f = x - j;
      for (var c = 0; c < 3; c++) t[3 * i + c] = pts[j][c] + (pts[j + 1][c] - pts[j][c]) * f;
    }
    LUT[k] = t;
  });
  var SRGB = new Uint8ClampedArray(4097);  // sRGB encoding of [0, 1] in 4096 steps
  for (var i = 0; i <= 4096; i++) {
    var x = i / 4096;
    SRGB[i] = 255 * (x <= 0.0031308 ? 12.92 * x : 1.055 * Math.pow(x, 1 / 2.4) - 0.055) + 0.5;
  }
  var Z_RANGE = 5;  // z maps saturate at |z| = 5

  function inflate(text) {
    // the data file is decoded as x-user-defined: U+0000..U+007F are bytes 0..127, U+F780..U+F7FF 128..255
    var bytes = new Uint8Array(text.length);
    for (var i = 0; i < text.length; i++) { var c = text.charCodeAt(i); bytes[i] = c < 0x80 ? c : c - 0xF700; }
    var stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('deflate'));
    return new Response(stream).arrayBuffer().then(function (buf) { return new Uint8Array(buf); });
  }
  function decodeLayer(layer, n) {
    return inflate(layer.data).then(function (b) {
      var total = b.length / 2, out = {};
      layer.channels.forEach(function (name, k) {
        var a = new Float32Array(n);
        for (var i = 0; i < n; i++) { var j = k * n + i; a[i] = HALF[b[j] | (b[total + j] << 8)]; }
        out[name] = a;
      });
      return out;
    });
  }
  var files = {};
  function script(url, charset) {  // what the data file at url passes to spectralBench.data or .markup
    return new Promise(function (resolve, reject) {
      var s = document.createElement('script');
      if (charset) s.charset = charset;
      s.src = url; s.spectralBenchResolve = resolve;
      s.onerror = function () { reject(new Error('cannot load ' + url)); };
      document.head.appendChild(s);
    });
  }
  function load(url) {
    if (!files[url]) files[url] = script(url, 'x-user-defined').then(function (obj) {
      var n = obj.w * obj.h, names = Object.keys(obj.layers);
      return Promise.all(names.map(function (k) { return decodeLayer(obj.layers[k], n); })).then(function (ls) {
        var out = {w: obj.w, h: obj.h};
        names.forEach(function (k, i) { out[k] = ls[i]; });
        return out;
      });
    });
    return files[url];
  }
  function data(script, obj) { if (script && script.spectralBenchResolve) script.spectralBenchResolve(obj); }

  function fmt(v) {
    if (v === undefined) return '-';
    if (!isFinite(v)) return String(v);
    var a = Math.abs(v);
    return a !== 0 && (a < 1e-3 || a >= 1e4) ? v.toExponential(3) : v.toPrecision(4);
  }
  function pct(values, q) {  // the q-quantile of |values| (a sample of at most 65536)
    var step = Math.max(1, Math.floor(values.length / 65536)), s = [];
    for (var i = 0; i < values.length; i += step) if (isFinite(values[i])) s.push(Math.abs(values[i]));
    s.sort(function (a, b) { return a - b; });
    return s.length ? s[Math.min(s.length - 1, Math.floor(q * s.length))] : 0;
  }

  // ---- one viewer: a job's render with its reference, z and FLIP maps --------------------------------
  function Viewer(box) {
    this.box = box; this.id = box.id;
    this.view = box.dataset.active; this.bview = 'reference';
    this.ev = 0; this.tf = 'srgb'; this.channel = null; this.diffRange = null;
    this.scale = 1; this.ox = 0; this.oy = 0; this.side = false;
    this.panes = [box.querySelector('canvas.pane-a'), box.querySelector('canvas.pane-b')];
    this.readout = box.querySelector('.readout'); this.bar = box.querySelector('.colourbar');
    this.status = box.querySelector('.load-status');
    this.loaded = false; this.loading = false;
  }
  Viewer.prototype.start = function () {
    if (this.loading) return;
    this.loading = true;
    var self = this, urls = [this.box.dataset.src, this.box.dataset.ref].filter(Boolean);
    this.status.textContent = 'loading float data...';
    Promise.all(urls.map(load)).then(function (parts) {
      var job = parts[0];
      self.w = job.w; self.h = job.h; self.render = job.render; self.stderr = job.stderr; self.blockse = job.blockse;
      self.z = job.z; self.flip = job.flip && job.flip.Y;
      self.probe = job.probe;  // the GGX probe's expected image and block z (probe views, below)
      if (parts[1] && parts[1].w === job.w && parts[1].h === job.h) self.ref = parts[1].reference;
      if (!self.channel) self.channel = self.worstChannel();
      var sel = self.box.querySelector('select.channel'); if (sel) sel.value = self.channel;
      self.loaded = true; self.status.textContent = '';
      self.box.dataset.ready = '1';
      self.fit(); self.draw();
      if (self.scrollTarget) self.scrollTarget.scrollIntoView();  // a #view= link: again, now that the page's height is final
    }).catch(function (e) { self.status.textContent = 'float data not shown: ' + e.message; self.box.dataset.ready = 'error'; });
  };
  Viewer.prototype.worstChannel = function () {
    if (!this.z) return 'R';
    var best = 'R', top = -1;
    ['R', 'G', 'B'].forEach(function (c) {
      var a = this.z[c]; if (!a) return;
      for (var i = 0; i < a.length; i++) { var v = Math.abs(a[i]); if (v > top) { top = v; best = c; } }
    }, this);
    return best;
  };
  Viewer.prototype.fit = function () {
    var width = Math.min(this.box.querySelector('.frames').clientWidth || 640, 720);
    if (this.side) width = Math.floor(width / 2) - 4;
    this.base = Math.min(width / this.w, 512 / this.h, 2);
    this.panes.forEach(function (c) {
      c.width = Math.round(this.w * this.base); c.height = Math.round(this.h * this.base);
    }, this);
    this.scale = this.base; this.ox = 0; this.oy = 0;
  };
  // the linear values a view shows at pixel i: [[label, value], ...] and its colour
  Viewer.prototype.pixelColour = function (view, i, out) {
    var c = this.channel, r = this.render, ref = this.ref, k = Math.pow(2, this.ev), v, t, lut;
    if (view === 'render' || view === 'reference' || view === 'S0') {
      var src = view === 'render' ? r : view === 'reference' ? ref : {R: r['S0.R'], G: r['S0.G'], B: r['S0.B']};
      if (!src) { out[0] = out[1] = out[2] = 40; return; }
      if (this.tf === 'false') {
        var y = (0.2126 * src.R[i] + 0.7152 * src.G[i] + 0.0722 * src.B[i]) * k;
        t = y > 0 ? (Math.log2(y) + 10) / 12 : 0;  // 2^-10 .. 2^2 after exposure
        lut = LUT.viridis; v = Math.max(0, Math.min(255, Math.round(t * 255)));
        out[0] = lut[3 * v]; out[1] = lut[3 * v + 1]; out[2] = lut[3 * v + 2];
      } else {
        out[0] = SRGB[Math.max(0, Math.min(4096, Math.round(src.R[i] * k * 4096)))] || 0;
        out[1] = SRGB[Math.max(0, Math.min(4096, Math.round(src.G[i] * k * 4096)))] || 0;
        out[2] = SRGB[Math.max(0, Math.min(4096, Math.round(src.B[i] * k * 4096)))] || 0;
      }
      return;
    }
    if (view === 'probe residual' || view === 'probe z') { this.probeColour(view, i, out); return; }
    if (view === 'difference') { t = 0.5 + (r[c][i] - ref[c][i]) / (2 * this.diffRange); lut = LUT.diverging; }
    else if (view === 'z-score') { t = 0.5 + this.z[c][i] / (2 * Z_RANGE); lut = LUT.diverging; }
    else if (view === 'FLIP') { t = this.flip[i]; lut = LUT.magma; }
    else if (view === 'S1' || view === 'S2' || view === 'S3') {
      t = 0.5 + r[view + '.' + c][i] / (2 * Math.max(Math.abs(r['S0.' + c][i]), 1e-30)); lut = LUT.diverging;
    } else if (view === 'DoP') { t = this.dop(i, c); lut = LUT.viridis; }
    else if (view === 'AoP') {
      t = (this.aop(i, c) + 90) / 180; lut = LUT.cyclic;
      var d = Math.min(1, this.dop(i, c));
      v = Math.max(0, Math.min(255, Math.round((isFinite(t) ? t : 0) * 255)));
      out[0] = lut[3 * v] * d; out[1] = lut[3 * v + 1] * d; out[2] = lut[3 * v + 2] * d;
      return;
    }
    v = Math.max(0, Math.min(255, Math.round((isFinite(t) ? t : 0.5) * 255)));
    out[0] = lut[3 * v]; out[1] = lut[3 * v + 1]; out[2] = lut[3 * v + 2];
  };
  Viewer.prototype.dop = function (i, c) {
    var r = this.render, s0 = r['S0.' + c][i], s1 = r['S1.' + c][i], s2 = r['S2.' + c][i], s3 = r['S3.' + c][i];
    return s0 > 0 ? Math.sqrt(s1 * s1 + s2 * s2 + s3 * s3) / s0 : 0;
  };
  Viewer.prototype.aop = function (i, c) {
    return 0.5 * Math.atan2(this.render['S2.' + c][i], this.render['S1.' + c][i]) * 180 / Math.PI;
  };
  Viewer.prototype.picture = function (view) {  // the view at 1 image pixel per pixel, in an offscreen canvas
    if (/^probe /.test(view) && this.probeRange === undefined) this.probeRange = this.probeSpread();
    var key = [view, this.ev, this.tf, this.channel, this.diffRange].join('|');
    this.cache = this.cache || {};
    if (this.cache[view] && this.cache[view].key === key) return this.cache[view].canvas;
    var w = this.w, h = this.h, cv = (this.cache[view] && this.cache[view].canvas) || document.createElement('canvas');
    cv.width = w; cv.height = h;
    var ctx = cv.getContext('2d'), img = ctx.createImageData(w, h), px = img.data, o = [0, 0, 0];
    if (view === 'difference' && this.diffRange === null) {
      var d = new Float32Array(w * h * 3), j = 0;
      ['R', 'G', 'B'].forEach(function (c) { for (var i = 0; i < w * h; i++) d[j++] = this.render[c][i] - this.ref[c][i]; }, this);
      this.diffRange = pct(d, 0.995) || 1e-6;
      key = [view, this.ev, this.tf, this.channel, this.diffRange].join('|');
    }
    for (var i = 0; i < w * h; i++) {
      this.pixelColour(view, i, o);
      px[4 * i] = o[0]; px[4 * i + 1] = o[1]; px[4 * i + 2] = o[2]; px[4 * i + 3] = 255;
    }
    ctx.putImageData(img, 0, 0);
    this.cache[view] = {key: key, canvas: cv};
    return cv;
  };
  Viewer.prototype.draw = function () {
    if (!this.loaded) return;
    var views = [this.view, this.bview];
    this.panes.forEach(function (c, k) {
      c.style.display = k === 0 || this.side ? '' : 'none';
      if (k === 1 && !this.side) return;
      var ctx = c.getContext('2d');
      ctx.imageSmoothingEnabled = false;
      ctx.fillStyle = '#555'; ctx.fillRect(0, 0, c.width, c.height);
      ctx.drawImage(this.picture(views[k]), this.ox, this.oy, this.w * this.scale, this.h * this.scale);
      this.overlay(ctx, views[k]);
      this.prismMarks(ctx);
    }, this);
    this.legend();
    this.box.dataset.active = this.view;
    this.box.querySelectorAll('.tabs button').forEach(function (b) { b.classList.toggle('active', b.dataset.view === this.view); }, this);
  };
  Viewer.prototype.overlay = function (ctx, view) {  // probe regions, drawn at their pixel boxes
    var regions = this.regions || (this.regions = JSON.parse(this.box.dataset.regions || '[]'));
    if (!regions.length || !this.box.querySelector('.show-probes').checked) return;
    var s = this.scale, ox = this.ox, oy = this.oy;
    ctx.lineWidth = 1; ctx.font = '11px sans-serif';
    regions.forEach(function (g) {
      var x0 = ox + g.box[0] * s, y0 = oy + g.box[1] * s, w = (g.box[2] - g.box[0]) * s, h = (g.box[3] - g.box[1]) * s;
      if (g.expected && (view === 'render' || view === 'reference')) {  // split square: expected on the left half
        var e = g.expected.map(function (x) { return SRGB[Math.max(0, Math.min(4096, Math.round(x * Math.pow(2, this.ev) * 4096)))]; }, this);
        ctx.fillStyle = 'rgb(' + e.join(',') + ')';
        ctx.fillRect(x0, y0, w / 2, h);
      }
      ctx.strokeStyle = g.pass === false ? '#ff2020' : g.pass === true ? '#20ff60' : '#ffd000';
      ctx.strokeRect(x0 + 0.5, y0 + 0.5, w, h);
      var tw = ctx.measureText(g.label || '').width;
      if (g.label && h > 14 && w > tw + 4) { ctx.fillStyle = '#000a'; ctx.fillRect(x0 + 1, y0 + h - 13, tw + 4, 12);
        ctx.fillStyle = '#fff'; ctx.fillText(g.label, x0 + 3, y0 + h - 3); }
    }, this);
  };
  Viewer.prototype.legend = function () {
    var v = this.view, bar = this.bar, c = this.channel, lo, hi, map, caption;
    if (v === 'difference') { map = 'diverging'; lo = -this.diffRange; hi = this.diffRange;
      caption = 'render - reference, channel ' + c + ' (linear; |d| >= ' + fmt(hi) + ' saturated: 99.5th percentile of |d| over R, G, B)'; }
    else if (v === 'z-score') { map = 'diverging'; lo = -Z_RANGE; hi = Z_RANGE;
      caption = 'z of the noise test per block, channel ' + c + ' (|z| >= ' + Z_RANGE + ' saturated)'; }
    else if (v === 'FLIP') { map = 'magma'; lo = 0; hi = 1; caption = 'HDR-FLIP error (0: none, 1: most)'; }
    else if (v === 'probe residual') { map = 'diverging'; lo = -this.probeRange; hi = this.probeRange;
      caption = 'GGX probe: render - expected (closed form), channel ' + c + ', on the plate (linear; |r| >= ' + fmt(hi)
        + ' saturated: 99.5th percentile of |r| over R, G, B; grey: off the plate)'; }
    else if (v === 'probe z') { map = 'diverging'; lo = -Z_RANGE; hi = Z_RANGE;
      caption = 'GGX probe: z of its test per block (block mean residual / its standard error), channel ' + c
        + ' (|z| >= ' + Z_RANGE + ' saturated; grey: off the plate)'; }
    else if (v === 'S1' || v === 'S2' || v === 'S3') { map = 'diverging'; lo = -1; hi = 1;
      caption = v + ' / S0, channel ' + c + (v === 'S1' ? ' (+1 horizontal, -1 vertical)' : v === 'S2' ? ' (+1 at +45 deg, -1 at -45 deg)' : ' (circular)'); }
    else if (v === 'DoP') { map = 'viridis'; lo = 0; hi = 1; caption = 'degree of polarisation, channel ' + c; }
    else if (v === 'AoP') { map = 'cyclic'; lo = -90; hi = 90;
      caption = 'angle of polarisation (deg, 0 horizontal, counter-clockwise as seen from the camera), channel ' + c + '; brightness = DoP'; }
    else if (this.tf === 'false') { map = 'viridis'; lo = Math.pow(2, -10 - this.ev); hi = Math.pow(2, 2 - this.ev);
      caption = 'luminance (linear, log scale) at ' + this.ev + ' EV'; }
    else { bar.style.display = 'none'; return; }
    bar.style.display = '';
    var cv = bar.querySelector('canvas'), ctx = cv.getContext('2d'), lut = LUT[map];
    for (var x = 0; x < cv.width; x++) {
      var k = Math.round(x / (cv.width - 1) * 255);
      ctx.fillStyle = 'rgb(' + lut[3 * k] + ',' + lut[3 * k + 1] + ',' + lut[3 * k + 2] + ')';
      ctx.fillRect(x, 0, 1, cv.height);
    }
    bar.querySelector('.lo').textContent = fmt(lo);
    bar.querySelector('.hi').textContent = fmt(hi);
    bar.querySelector('.caption').textContent = caption;
  };
  Viewer.prototype.pixelAt = function (canvas, ev) {  // the canvas's content box: its border is not image
    var r = canvas.getBoundingClientRect(), mx = (ev.clientX - r.left - canvas.clientLeft) * canvas.width / (canvas.clientWidth || r.width),
      my = (ev.clientY - r.top - canvas.clientTop) * canvas.height / (canvas.clientHeight || r.height);
    return {mx: mx, my: my, x: Math.floor((mx - this.ox) / this.scale), y: Math.floor((my - this.oy) / this.scale)};
  };
  Viewer.prototype.read = function (x, y) {  // the readout of one pixel: every value is the data's
    if (!this.loaded || x < 0 || y < 0 || x >= this.w || y >= this.h) { this.readout.textContent = ''; return; }
    var i = y * this.w + x, lines = ['pixel x ' + x + ', y ' + y + ' (from the top left; half floats: 4 significant digits)'];
    var row = function (label, src, names) {
      if (!src) return;
      lines.push(label + ': ' + names.map(function (n) { return n + ' ' + fmt(src[n] ? src[n][i] : undefined); }).join('  '));
    };
    row('render', this.render, ['R', 'G', 'B']);
    row('reference', this.ref, ['R', 'G', 'B']);
    if (this.ref) lines.push('difference: ' + ['R', 'G', 'B'].map(function (n) { return n + ' ' + fmt(this.render[n][i] - this.ref[n][i]); }, this).join('  '));
    row('standard error (render, 2 digits)', this.stderr, ['R', 'G', 'B']);  // a run from before block_stderr.exr
    row('standard error of the block\'s difference (render and reference noise; z divides by it)', this.blockse, ['R', 'G', 'B']);
    row('z (block)', this.z, ['R', 'G', 'B']);
    if (this.flip) lines.push('FLIP: ' + fmt(this.flip[i]));
    this.probeLines(i, lines);
    if (this.render['S0.R']) {
      ['S0', 'S1', 'S2', 'S3'].forEach(function (s) { row(s, this.render, [s + '.R', s + '.G', s + '.B']); }, this);
      lines.push('DoP: ' + ['R', 'G', 'B'].map(function (c) { return c + ' ' + fmt(this.dop(i, c)); }, this).join('  ')
        + '   AoP (deg): ' + ['R', 'G', 'B'].map(function (c) { return c + ' ' + fmt(this.aop(i, c)); }, this).join('  '));
    }
    this.readout.textContent = lines.join('\n');
    this.box.dataset.pixel = x + ',' + y;
  };
  Viewer.prototype.bind = function () {
    var self = this, drag = null;
    this.panes.forEach(function (c) {
      c.addEventListener('mousemove', function (ev) {
        active = self;
        var p = self.pixelAt(c, ev);
        if (drag) { self.ox += p.mx - drag.mx; self.oy += p.my - drag.my; drag = p; self.draw(); }
        self.read(p.x, p.y);
      });
      c.addEventListener('mousedown', function (ev) { drag = self.pixelAt(c, ev); ev.preventDefault(); });
      c.addEventListener('wheel', function (ev) {  // zoom at the cursor: the pixel under it stays put
        ev.preventDefault();
        var p = self.pixelAt(c, ev), f = ev.deltaY < 0 ? 1.25 : 0.8;
        var s = Math.max(self.base / 2, Math.min(self.scale * f, 64));
        f = s / self.scale; self.scale = s;
        self.ox = p.mx - (p.mx - self.ox) * f; self.oy = p.my - (p.my - self.oy) * f;
        self.draw();
      }, {passive: false});
    });
    window.addEventListener('mouseup', function () { drag = null; });
    var on = function (sel, evt, fn) { var e = self.box.querySelector(sel); if (e) e.addEventListener(evt, fn); };
    on('.exposure', 'input', function (ev) { self.ev = parseFloat(ev.target.value); self.box.querySelector('.ev').textContent = ev.target.value; self.draw(); });
    on('.transform', 'change', function (ev) { self.tf = ev.target.value; self.draw(); });
    on('.channel', 'change', function (ev) { self.channel = ev.target.value; self.draw(); });
    on('.side', 'change', function (ev) { self.side = ev.target.checked; self.fit(); self.draw(); });
    on('.bview', 'change', function (ev) { self.bview = ev.target.value; self.draw(); });
    on('.show-probes', 'change', function () { self.draw(); });
    on('.reset', 'click', function () { self.fit(); self.draw(); });
    on('.flip-ab', 'click', function () { self.flipAB(); });
  };
  Viewer.prototype.show = function (view) {
    if (!this.box.querySelector('.tabs button[data-view="' + view + '"]')) return;
    this.view = view; this.box.dataset.active = view;
    this.box.querySelectorAll('.tabs button').forEach(function (b) { b.classList.toggle('active', b.dataset.view === view); });
    var sel = this.box.querySelector('.channel-box');
    if (sel) sel.style.visibility = /^(difference|z-score|S[123]|DoP|AoP|probe residual|probe z)$/.test(view) ? '' : 'hidden';
    this.draw();
  };
  // ---- probes drawn on the image (issue 21 item 4) ------------------------------------------------------
  // The GGX probe's residual map (batch/verdict/probes/ggx.py residual_map, probe_residual.exr): its
  // expected image per plate pixel (NaN off the plate) and the z of each pixel's block in its test.
  Viewer.prototype.probeResidual = function (c, i) {  // render - expected: the residual the probe averages
    var e = this.probe['expected.' + c];
    return e ? this.render[c][i] - e[i] : NaN;
  };
  Viewer.prototype.probeSpread = function () {  // the 99.5th percentile of |residual| over the plates, R, G, B
    if (!this.probe) return 1e-6;
    var d = [];
    ['R', 'G', 'B'].forEach(function (c) {
      for (var i = 0; i < this.w * this.h; i++) { var x = this.probeResidual(c, i); if (isFinite(x)) d.push(x); }
    }, this);
    return pct(d, 0.995) || 1e-6;
  };
  Viewer.prototype.probeColour = function (view, i, out) {
    var c = this.channel, t = view === 'probe z' ? this.probe['z.' + c][i] / (2 * Z_RANGE) + 0.5
      : this.probeResidual(c, i) / (2 * this.probeRange) + 0.5;
    if (!isFinite(t)) {  // off the plate: the render's luminance, dimmed grey (for orientation)
      var r = this.render, y = 0.2126 * r.R[i] + 0.7152 * r.G[i] + 0.0722 * r.B[i];
      out[0] = out[1] = out[2] = (SRGB[Math.max(0, Math.min(4096, Math.round(y * Math.pow(2, this.ev) * 4096)))] || 0) * 0.35;
      return;
    }
    var v = Math.max(0, Math.min(255, Math.round(t * 255))), lut = LUT.diverging;
    out[0] = lut[3 * v]; out[1] = lut[3 * v + 1]; out[2] = lut[3 * v + 2];
  };
  Viewer.prototype.probeLines = function (i, lines) {  // the readout's probe rows, on the plate only
    var p = this.probe, m = this.markData();
    if (m) {  // the prism: where this pixel's centre lies along the fan, as the marks count
      var x = i % this.w + 0.5, y = Math.floor(i / this.w) + 0.5;
      lines.push('prism: pixel centre at ' + fmt((x - m.origin[0]) * m.u[0] + (y - m.origin[1]) * m.u[1])
        + ' px along the fan from 550 nm\'s band centre');
    }
    if (!p || !isFinite(p['expected.R'] ? p['expected.R'][i] : NaN)) return;
    var rgb = ['R', 'G', 'B'];
    lines.push('GGX probe expected: ' + rgb.map(function (c) { return c + ' ' + fmt(p['expected.' + c][i]); }).join('  '));
    lines.push('GGX probe residual (render - expected): ' + rgb.map(function (c) { return c + ' ' + fmt(this.probeResidual(c, i)); }, this).join('  '));
    lines.push('GGX probe z (its block): ' + rgb.map(function (c) { return c + ' ' + fmt(p['z.' + c][i]); }).join('  '));
  };
  // The prism's band positions (html.py _prism_marks, from the positions probe's record): a tick at
  // origin + s u (image pixels) for each position s, across the fan: the wavelengths' ticks above
  // the band (as the image shows it), the channels' centroids below it, each channel's expected
  // tick next to the band and its measured tick right after it, so that where they agree they
  // make one line.
  var MARK_COLOUR = {R: '#ff4040', G: '#30e030', B: '#4080ff', wavelength: '#ffffff'};
  Viewer.prototype.markData = function () {
    return this.marks !== undefined ? this.marks : (this.marks = JSON.parse(this.box.dataset.marks || 'null'));
  };
  Viewer.prototype.prismMarks = function (ctx) {
    var m = this.markData();
    var show = this.box.querySelector('.show-probes');
    if (!m || (show && !show.checked)) return;
    var s = this.scale, ox = this.ox, oy = this.oy, u = m.u;
    var n = u[0] >= 0 ? [u[1], -u[0]] : [-u[1], u[0]];  // perpendicular to the fan, pointing up the image
    if (n[1] > 0) n = [-n[0], -n[1]];
    var gap = m.half * s + 3, L = 9;
    var at = function (pos, d) {  // canvas point of fan position pos, d canvas pixels along n
      return [ox + (m.origin[0] + pos * u[0]) * s + d * n[0], oy + (m.origin[1] + pos * u[1]) * s + d * n[1]];
    };
    var line = function (pos, d0, d1, colour) {
      var a = at(pos, d0), b = at(pos, d1);
      ctx.strokeStyle = colour; ctx.lineWidth = 2; ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke();
    };
    var label = function (text, p, colour) {  // left-aligned at p
      var w = ctx.measureText(text).width;
      ctx.fillStyle = '#000c'; ctx.fillRect(p[0] - 2, p[1] - 6, w + 4, 12);
      ctx.fillStyle = colour; ctx.fillText(text, p[0], p[1] + 4);
    };
    ctx.font = '11px sans-serif';
    // label rows, 13 px apart: a label starts at its tick and runs along the fan, so it takes the
    // row above every tick it would cover, and its tick reaches to it (a staircase that no tick
    // line crosses)
    var rows = function (ticks) {
      var placed = [];
      ticks.slice().sort(function (a, b) { return b.s - a.s; }).forEach(function (t) {
        var x = t.s * s * (u[0] >= 0 ? 1 : -1), w = ctx.measureText(t.label).width;
        t.row = 0;
        placed.forEach(function (q) { if (q.x >= x - 1 && q.x <= x + w + 6) t.row = Math.max(t.row, q.t.row + 1); });
        placed.push({x: x, t: t});
      });
    };
    var waves = m.ticks.filter(function (t) { return t.kind === 'wavelength'; });
    var measured = m.ticks.filter(function (t) { return t.kind === 'measured'; });
    rows(waves); rows(measured);
    waves.forEach(function (t) { line(t.s, gap, gap + L + 13 * t.row, MARK_COLOUR.wavelength); });
    m.ticks.forEach(function (t) { if (t.kind === 'expected') line(t.s, -gap, -gap - L, MARK_COLOUR[t.channel]); });
    measured.forEach(function (t) { line(t.s, -gap - L, -gap - 2 * L - 13 * t.row, MARK_COLOUR[t.channel]); });
    waves.forEach(function (t) { label(t.label, at(t.s, gap + L + 13 * t.row + 6), MARK_COLOUR.wavelength); });
    measured.forEach(function (t) { label(t.label, at(t.s, -gap - 2 * L - 13 * t.row - 6), MARK_COLOUR[t.channel]); });
  };
  Viewer.prototype.flipAB = function () { this.show(this.view === 'render' ? 'reference' : 'render'); };


  // ---- a spectral job's bands (issue 33): the preview at one band, and the regions' spectra ------------
  // Nothing loads before the section is opened: the plots wait in a <template>, the band data
  // (spectral_preview.js, one plane per band, html.py _spectral_data) in its script file.
  function Spectra(box) {
    this.box = box; this.ev = 0; this.band = 0;
    this.bands = JSON.parse(box.dataset.bands || '[]');
    this.canvas = box.querySelector('canvas.band-canvas');
    this.status = box.querySelector('.load-status'); this.readout = box.querySelector('.band-readout');
  }
  Spectra.prototype.open = function () {
    if (this.started) return;
    this.started = true;
    var self = this, slider = this.box.querySelector('input.band'), plots = this.box.querySelector('.plots'), got = [];
    if (this.box.dataset.plots) got.push(script(this.box.dataset.plots).then(function (markup) { plots.innerHTML = markup; }));
    if (!this.box.dataset.src) {
      Promise.all(got).then(function () { self.box.dataset.ready = '1'; }, function (e) { plots.textContent = 'plots not shown: ' + e.message; self.box.dataset.ready = 'error'; });
      return;
    }
    this.status.textContent = 'loading band data...';
    got.push(load(this.box.dataset.src));
    Promise.all(got).then(function (parts) {
      var d = parts[parts.length - 1];
      self.w = d.w; self.h = d.h; self.data = d.bands;
      slider.max = String(self.bands.length - 1);
      slider.value = String(self.band = Math.floor((self.bands.length - 1) / 2));
      var k = Math.min(8, Math.max(1, 360 / Math.max(d.w, d.h)));  // shown at least 360 px on its longer side (up to 8x)
      self.canvas.width = d.w; self.canvas.height = d.h;
      self.canvas.style.width = Math.round(d.w * k) + 'px'; self.canvas.style.height = Math.round(d.h * k) + 'px';
      self.status.textContent = ''; self.draw(); self.box.dataset.ready = '1';
    }).catch(function (e) { self.status.textContent = 'band data not shown: ' + e.message; self.box.dataset.ready = 'error'; });
    slider.addEventListener('input', function () { self.band = parseInt(slider.value, 10); self.draw(); });
    var ev = this.box.querySelector('input.band-exposure');
    ev.addEventListener('input', function () { self.ev = parseFloat(ev.value); self.box.querySelector('.band-ev').textContent = ev.value; self.draw(); });
    this.canvas.addEventListener('mousemove', function (e) {
      var r = self.canvas.getBoundingClientRect(), x = Math.floor((e.clientX - r.left - self.canvas.clientLeft) * self.w / self.canvas.clientWidth),
        y = Math.floor((e.clientY - r.top - self.canvas.clientTop) * self.h / self.canvas.clientHeight);
      if (!self.data || x < 0 || y < 0 || x >= self.w || y >= self.h) return;
      self.readout.textContent = 'pixel x ' + x + ', y ' + y + ': ' + fmt(self.data[String(self.band)][y * self.w + x]) + ' at ' + self.bands[self.band].label;
    });
  };
  Spectra.prototype.draw = function () {
    var a = this.data[String(this.band)], ctx = this.canvas.getContext('2d'), img = ctx.createImageData(this.w, this.h), px = img.data, k = Math.pow(2, this.ev);
    for (var i = 0; i < a.length; i++) {
      var g = SRGB[Math.max(0, Math.min(4096, Math.round(a[i] * k * 4096)))] || 0;
      px[4 * i] = px[4 * i + 1] = px[4 * i + 2] = g; px[4 * i + 3] = 255;
    }
    ctx.putImageData(img, 0, 0);
    this.box.querySelector('.band-nm').textContent = this.bands[this.band].label;
    this.box.dataset.band = String(this.band);
  };
  var spectraBoxes = {};
  function spectra(id) { return spectraBoxes[id]; }

  var viewers = {}, active = null;
  function viewer(id) { return viewers[id]; }
  function init() {
    var boxes = document.querySelectorAll('.viewer[data-src]');
    var io = 'IntersectionObserver' in window ? new IntersectionObserver(function (entries) {
      entries.forEach(function (e) { if (e.isIntersecting) viewers[e.target.id].start(); });
    }, {rootMargin: '400px'}) : null;
    boxes.forEach(function (box) {
      var v = new Viewer(box);
      viewers[box.id] = v; v.bind(); v.show(v.view);
      box.addEventListener('mouseenter', function () { active = v; });
      if (io) io.observe(box); else v.start();
    });
    document.querySelectorAll('details.spectra').forEach(function (box) {
      var sp = spectraBoxes[box.id] = new Spectra(box);
      box.addEventListener('toggle', function () { if (box.open) sp.open(); });
      if (box.open) sp.open();
    });
    document.addEventListener('keydown', function (ev) {  // A/B flip of the viewer under the mouse
      if (!active || ev.target.tagName === 'INPUT' || ev.target.tagName === 'SELECT') return;
      if (ev.key === 'f' || ev.key === 'F') { active.flipAB(); ev.preventDefault(); }
    });
  }
  return {data: data, markup: data, init: init, viewer: viewer, spectra: spectra, load: load, HALF: HALF, SRGB: SRGB};
})();
