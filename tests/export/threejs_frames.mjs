// What three.js shows of an animated GLB at given times, as JSON on stdout.
//
//   node threejs_frames.mjs THREE_DIR FILE.glb T0 [T1 ...]
//
// three.js's own GLTFLoader parses the file and an AnimationMixer plays its first
// animation to each time; every mesh's colours are then what three.js's vertex
// shader computes (morphcolor_vertex with relative targets: base colour plus the sum
// of influence x morph colour) and its positions the morphed ones through the mesh's
// world matrix.  Output: [{time, meshes: {name: {color: [[r,g,b]...], position: ...}}}].
import { readFileSync } from "node:fs";
import { pathToFileURL } from "node:url";

const [threeDir, file, ...times] = process.argv.slice(2);
const THREE = await import(pathToFileURL(`${threeDir}/build/three.module.js`).href);
const { GLTFLoader } = await import(
  pathToFileURL(`${threeDir}/examples/jsm/loaders/GLTFLoader.js`).href);

const bytes = readFileSync(file);
const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
const gltf = await new Promise((resolve, reject) =>
  new GLTFLoader().parse(buffer, "", resolve, reject));

const mixer = new THREE.AnimationMixer(gltf.scene);
if (gltf.animations.length) mixer.clipAction(gltf.animations[0]).play();
const v = new THREE.Vector3();
const out = [];
for (const time of times.map(Number)) {
  mixer.setTime(time);
  gltf.scene.updateMatrixWorld(true);
  const meshes = {};
  gltf.scene.traverse((mesh) => {
    if (!mesh.isMesh) return;
    const g = mesh.geometry;
    const influences = mesh.morphTargetInfluences || [];
    const base = g.morphTargetsRelative ? 1 : 1 - influences.reduce((a, b) => a + b, 0);
    const color = [], position = [];
    for (let i = 0; i < g.attributes.position.count; i++) {
      const c = [0, 1, 2].map((k) => g.attributes.color.getComponent(i, k) * base);
      v.fromBufferAttribute(g.attributes.position, i).multiplyScalar(base);
      influences.forEach((w, t) => {
        if (w === 0) return;
        const mc = g.morphAttributes.color?.[t];
        if (mc) for (let k = 0; k < 3; k++) c[k] += w * mc.getComponent(i, k);
        const mp = g.morphAttributes.position?.[t];
        if (mp) v.add(new THREE.Vector3().fromBufferAttribute(mp, i).multiplyScalar(w));
      });
      v.applyMatrix4(mesh.matrixWorld);
      color.push(c);
      position.push([v.x, v.y, v.z]);
    }
    meshes[mesh.name] = { color, position };
  });
  out.push({ time, meshes });
}
process.stdout.write(JSON.stringify(out));
