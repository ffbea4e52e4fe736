// Build twinkit/report_assets/three-bundle.js once, at set-up (scripts/setup.sh: `npm run bundle`):
// three.js, GLTFLoader and OrbitControls as one classic script that defines window.TWINKIT_THREE.
// Report pages are opened from file://, where browsers refuse ES-module imports, so the report copies
// this one script (and three's licence) into every report instead of loading modules.
import { build } from "esbuild";
import { copyFileSync, readFileSync, renameSync, writeFileSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";

const root = join(dirname(fileURLToPath(import.meta.url)), "..");
const assets = join(root, "twinkit", "report_assets");
const three = join(root, "node_modules", "three");
const version = JSON.parse(readFileSync(join(three, "package.json"), "utf8")).version;

const entry = `
import * as THREE from "three";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
window.TWINKIT_THREE = { THREE, GLTFLoader, OrbitControls, version: ${JSON.stringify(version)} };
`;

const result = await build({
  stdin: { contents: entry, resolveDir: root, sourcefile: "three-entry.js", loader: "js" },
  bundle: true,
  format: "iife",
  target: "es2020",
  legalComments: "inline",
  write: false,
  logLevel: "warning",
  banner: {
    js: `/* three.js ${version} (MIT License, Copyright 2010-2026 Three.js Authors; see three-LICENSE.txt),\n` +
        `   from the npm package 'three', bundled by esbuild (scripts/bundle-three.mjs) into one classic\n` +
        `   script so that the report works from file:// (browsers refuse ES-module imports there). */`,
  },
});

// written beside and renamed: reports hard-link this file, so it is replaced, never rewritten in place
const out = join(assets, "three-bundle.js");
writeFileSync(out + ".tmp", result.outputFiles[0].contents);
renameSync(out + ".tmp", out);
copyFileSync(join(three, "LICENSE"), join(assets, "three-LICENSE.txt"));
console.log(`bundle: ${out} (three.js ${version}, ${result.outputFiles[0].contents.length} bytes)`);
