/* twinkit run report: the interactive 3D view.
 * Needs three-bundle.js (window.TWINKIT_THREE: three.js, GLTFLoader, OrbitControls) and model.glb.js
 * (window.TWINKIT_GLB: the GLB, base64), both classic scripts so the page works from file://. The link
 * #viewer-download gets the decoded GLB (a blob), so the report holds the model once.
 * Colour modes: "texture" shows the material's texture, else the COLOR_0 vertex colours;
 * "segmentation" shows the _CLASS_COLOR attribute (twinkit's GLBs carry the segmentation colours there,
 * where they darken nothing in other viewers) with simple lighting. GLBs written before that convention
 * (segmentation in COLOR_0, texture colours in _TEXCOLOR) still show both.
 * State for tests and scripts: window.twinkitViewer = {ready, error, mode, frames, hasSegmentation, setMode}.
 */
(function () {
  'use strict';
  var statusEl = document.getElementById('viewer-status');
  var state = window.twinkitViewer = {
    ready: false, error: null, mode: 'texture', frames: 0, hasSegmentation: false, setMode: null
  };

  function say(msg) { if (statusEl) statusEl.textContent = msg; }
  function fail(msg) { state.error = msg; say(msg); }

  var T = window.TWINKIT_THREE;
  if (!T) { fail('3D view unavailable: three.js did not load'); return; }
  if (!window.TWINKIT_GLB) { fail('3D view unavailable: the model did not load'); return; }
  var THREE = T.THREE;
  var box = document.getElementById('viewer');
  var canvas = document.getElementById('viewer-canvas');

  var probe = canvas.getContext('webgl2') || canvas.getContext('webgl');
  if (!probe) { fail('3D view unavailable: this browser has no WebGL'); return; }
  var renderer = new THREE.WebGLRenderer({ canvas: canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));

  var scene = new THREE.Scene();
  scene.background = new THREE.Color(0xeef0f3);
  var camera = new THREE.PerspectiveCamera(45, 1.6, 0.05, 5000);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8f99, 2.2));
  var sun = new THREE.DirectionalLight(0xffffff, 1.6);
  sun.position.set(0.4, 1.0, 0.6);
  scene.add(sun);

  var controls = new T.OrbitControls(camera, canvas);
  controls.enableDamping = false;
  controls.screenSpacePanning = true;
  controls.maxPolarAngle = Math.PI * 0.495;

  var pending = false;
  function render() {
    if (pending) return;
    pending = true;
    requestAnimationFrame(function () {
      pending = false;
      renderer.render(scene, camera);
      state.frames += 1;
    });
  }
  controls.addEventListener('change', render);

  function resize() {
    var w = Math.max(200, box.clientWidth);
    var h = Math.round(Math.min(Math.max(260, w * 0.58), window.innerHeight * 0.8));
    renderer.setSize(w, h, false);
    canvas.style.width = w + 'px';
    canvas.style.height = h + 'px';
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    render();
  }
  window.addEventListener('resize', resize);

  function decode(b64) {
    if (Uint8Array.fromBase64) return Uint8Array.fromBase64(b64).buffer;
    var bin = atob(b64), n = bin.length, u = new Uint8Array(n);
    for (var i = 0; i < n; i++) u[i] = bin.charCodeAt(i);
    return u.buffer;
  }

  var parts = [];
  var home = null;

  function setMode(mode) {
    if (mode === 'segmentation' && !state.hasSegmentation) mode = 'texture';
    parts.forEach(function (p) {
      var g = p.mesh.geometry;
      if (mode === 'segmentation') {
        g.setAttribute('color', p.seg);
        p.mesh.material = p.segMat;
      } else {
        if (p.texAttr) g.setAttribute('color', p.texAttr);
        p.mesh.material = p.texMat;
      }
    });
    state.mode = mode;
    var radio = document.getElementById('mode-' + mode);
    if (radio) radio.checked = true;
    render();
  }
  state.setMode = setMode;

  function frame() {
    var b = new THREE.Box3();
    parts.forEach(function (p) { b.expandByObject(p.mesh); });
    if (b.isEmpty()) b.set(new THREE.Vector3(-1, -1, -1), new THREE.Vector3(1, 1, 1));
    var c = b.getCenter(new THREE.Vector3());
    var r = Math.max(b.getSize(new THREE.Vector3()).length() / 2, 0.5);
    home = { target: c.clone(), pos: c.clone().add(new THREE.Vector3(0.55, 0.75, 0.95).multiplyScalar(r * 1.35)) };
    camera.near = r / 500;
    camera.far = r * 20;
    controls.maxDistance = r * 8;
    resetView();
  }
  function resetView() {
    if (!home) return;
    camera.position.copy(home.pos);
    controls.target.copy(home.target);
    camera.updateProjectionMatrix();
    controls.update();
    render();
  }

  say('loading the model…');
  var buffer;
  try { buffer = decode(window.TWINKIT_GLB); } catch (e) { fail('3D view: the model is not valid base64'); return; }
  var download = document.getElementById('viewer-download');
  if (download && window.Blob && window.URL) {
    download.href = URL.createObjectURL(new Blob([buffer], { type: 'model/gltf-binary' }));
  }
  new T.GLTFLoader().parse(buffer, '', function (gltf) {
    var nverts = 0, ntris = 0;
    gltf.scene.traverse(function (o) {
      if (!o.isMesh) return;
      var g = o.geometry;
      var m0 = Array.isArray(o.material) ? o.material[0] : o.material;
      var map = (m0 && m0.map) || null;
      var col = g.getAttribute('color') || null;
      var cls = g.getAttribute('_class_color') || null;  // GLTFLoader lower-cases application attributes
      var tex = g.getAttribute('_texcolor') || null;  // the older convention: texture colours here, segmentation in COLOR_0
      if (!g.getAttribute('normal')) g.computeVertexNormals();
      var p = { mesh: o, map: map, seg: null, texAttr: null };
      if (cls) {
        p.seg = cls;
      } else if (tex || map) {
        p.seg = col;
      }
      if (tex && !cls) col = tex;
      // what the "texture" look draws: the texture, else the texture colours per vertex
      if (map) {
        p.texMat = new THREE.MeshBasicMaterial({ map: map, side: THREE.DoubleSide });
      } else if (col) {
        p.texAttr = col;
        p.texMat = new THREE.MeshBasicMaterial({ vertexColors: true, side: THREE.DoubleSide });
      } else {
        p.texMat = new THREE.MeshLambertMaterial({ color: 0xb8b8b8, side: THREE.DoubleSide });
      }
      if (p.seg) p.segMat = new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide });
      parts.push(p);
      nverts += g.getAttribute('position').count;
      ntris += (g.index ? g.index.count : g.getAttribute('position').count) / 3;
    });
    state.hasSegmentation = parts.length > 0 && parts.every(function (p) { return !!p.seg; });
    var segRadio = document.getElementById('mode-segmentation');
    if (segRadio && !state.hasSegmentation) {
      segRadio.disabled = true;
      segRadio.parentNode.title = 'no segmentation colours in this model yet';
      segRadio.parentNode.classList.add('disabled');
    }
    scene.add(gltf.scene);
    setMode('texture');
    resize();
    frame();
    say(nverts.toLocaleString('en') + ' vertices, ' + Math.round(ntris).toLocaleString('en') + ' triangles' +
        (state.hasSegmentation ? '' : ' · no segmentation colours yet'));
    requestAnimationFrame(function () { requestAnimationFrame(function () { state.ready = true; }); });
  }, function (err) {
    fail('3D view: cannot read the model (' + (err && err.message ? err.message : err) + ')');
  });

  Array.prototype.forEach.call(document.querySelectorAll('input[name="colours"]'), function (r) {
    r.addEventListener('change', function () { if (r.checked) setMode(r.value); });
  });
  var reset = document.getElementById('view-reset');
  if (reset) reset.addEventListener('click', resetView);
})();
