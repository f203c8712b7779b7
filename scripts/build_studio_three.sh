#!/usr/bin/env bash
# Rebuild the studio's vendored three.js (animegraph/apps/studio/static/vendor/three.min.js):
# three r187 from npm with its OrbitControls and GLTFLoader, bundled and minified by esbuild
# into one ES module exporting only what the page uses (r187 ships no minified module
# build). Needs npm (the registry); run from the repository's root.
set -euo pipefail
THREE_VERSION=0.187.0
ESBUILD_VERSION=0.28.2
out="$PWD/animegraph/apps/studio/static/vendor"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cd "$work"
npm init -y >/dev/null
npm install --no-audit --no-fund --ignore-scripts "three@$THREE_VERSION" >/dev/null
npm install --no-audit --no-fund "esbuild@$ESBUILD_VERSION" >/dev/null
# The names the page imports (face.js: `THREE.X`); add one here when the page needs it.
cat > entry.js <<'JS'
export { Box3, BufferAttribute, BufferGeometry, Color, DirectionalLight, DoubleSide,
  DynamicDrawUsage, Group, HemisphereLight, MathUtils, Mesh, MeshBasicMaterial,
  MeshLambertMaterial, MeshPhongMaterial, MeshStandardMaterial, PerspectiveCamera, Scene,
  SphereGeometry, Vector3, WebGLRenderer } from "three";
export { OrbitControls } from "three/addons/controls/OrbitControls.js";
export { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
JS
npx esbuild entry.js --bundle --format=esm --minify --legal-comments=inline \
    --outfile="$out/three.min.js" --log-level=warning
cp node_modules/three/LICENSE "$out/three-LICENSE.txt"
echo "wrote $out/three.min.js ($(wc -c < "$out/three.min.js") bytes)"
