#!/usr/bin/env bash
# Vendors three.js for the viewer page (python/topomech/web/three/): the parts of three.js
# (npm package `three`) and its OrbitControls that web/viewer.js uses, bundled by esbuild into
# one minified script that defines the global `THREE` (inlined into viewer.html: no network
# at run time), with three.js's MIT licence and the version.
# Usage: scripts/vendor_three.sh [VERSION]   (needs node and npm; run from anywhere)
set -euo pipefail
version="${1:-0.187.0}"
esbuild_version="0.28.2"
here="$(cd "$(dirname "$0")/.." && pwd)"
dest="$here/python/topomech/web/three"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cd "$work"
npm init -y >/dev/null
npm install --silent --no-audit --no-fund "three@$version" "esbuild@$esbuild_version" >/dev/null
cat > entry.js <<'JS'
export {
  AmbientLight, BufferAttribute, BufferGeometry, Color, DataTexture, DirectionalLight,
  DoubleSide, DynamicDrawUsage, FloatType, GLSL3, InstancedBufferGeometry, LineBasicMaterial,
  LineSegments, Mesh, MeshPhongMaterial, PerspectiveCamera, Points, Raycaster, REVISION,
  RGBAFormat, RGFormat, Scene, ShaderMaterial, Sphere, SRGBColorSpace, Vector2, Vector3,
  WebGLRenderer,
} from "three";
export { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
JS
npx esbuild entry.js --bundle --minify --format=iife --global-name=THREE \
  --target=es2020 --legal-comments=inline --outfile=three.min.js --log-level=warning
# inlined in a <script> element: nothing in it may end the element or open a comment
if grep -qi -e '</script' -e '<!--' three.min.js; then
  echo "vendor_three: the bundle contains </script or <!--" >&2
  exit 1
fi
mkdir -p "$dest"
cp three.min.js "$dest/three.min.js"
cp node_modules/three/LICENSE "$dest/LICENSE"
{
  echo "three.js $version (npm package \`three\`, MIT licence: LICENSE)"
  echo "three.min.js: esbuild $esbuild_version bundle of the classes web/viewer.js uses and"
  echo "examples/jsm/controls/OrbitControls.js, global THREE (scripts/vendor_three.sh)"
} > "$dest/VERSION"
echo "vendor_three: wrote $dest/three.min.js ($(wc -c < "$dest/three.min.js") bytes, three.js $version)"
