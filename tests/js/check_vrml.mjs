// Independent reader for shadeform's VRML export: parse a .wrl with three.js's VRMLLoader and
// print what it found as one JSON line. Exit 1 (message on stderr) if it cannot be parsed.
//
//   node tests/js/check_vrml.mjs mesh.wrl
//   -> {"meshes":1,"faces":F,"vertices":V,"normals":true,"uv":true,"frontFacing":F,
//       "min":[x,y,z],"max":[x,y,z]}
//
// VRMLLoader triangulates and un-indexes every IndexedFaceSet, so faces = positions / 3 and
// vertices = distinct positions. frontFacing counts triangles whose normal (from the winding
// three.js keeps) has z > 0, i.e. that face the viewer. parse(text, path) needs no DOM unless
// the scene has textures or a camera, which shadeform's files do not.
import { readFileSync } from 'node:fs';
import { VRMLLoader } from 'three/examples/jsm/loaders/VRMLLoader.js';

const file = process.argv[2];
if (!file) {
	process.stderr.write('usage: node check_vrml.mjs FILE.wrl\n');
	process.exit(2);
}

let scene;
// VRMLLoader reports parse errors with console.error before throwing; keep stdout clean
console.error = (...args) => process.stderr.write(args.map(String).join(' ') + '\n');
try {
	scene = new VRMLLoader().parse(readFileSync(file, 'utf8'), '');
} catch (err) {
	process.stderr.write(`VRMLLoader failed: ${err.message}\n`);
	process.exit(1);
}

let meshes = 0, faces = 0, frontFacing = 0, normals = true, uv = true;
const seen = new Set();
const min = [Infinity, Infinity, Infinity], max = [-Infinity, -Infinity, -Infinity];
scene.traverse((object) => {
	if (!object.isMesh) return;
	meshes += 1;
	const geometry = object.geometry;
	const position = geometry.getAttribute('position');
	normals &&= geometry.getAttribute('normal') !== undefined;
	uv &&= geometry.getAttribute('uv') !== undefined;
	if (geometry.index !== null) throw new Error('expected un-indexed geometry from VRMLLoader');
	faces += position.count / 3;
	for (let i = 0; i < position.count; i++) {
		const p = [position.getX(i), position.getY(i), position.getZ(i)];
		seen.add(p.join(' '));
		for (let k = 0; k < 3; k++) {
			min[k] = Math.min(min[k], p[k]);
			max[k] = Math.max(max[k], p[k]);
		}
	}
	for (let i = 0; i < position.count; i += 3) {
		const ax = position.getX(i + 1) - position.getX(i), ay = position.getY(i + 1) - position.getY(i);
		const bx = position.getX(i + 2) - position.getX(i), by = position.getY(i + 2) - position.getY(i);
		if (ax * by - ay * bx > 0) frontFacing += 1;
	}
});

if (meshes === 0) {
	process.stderr.write('VRMLLoader found no mesh in the file\n');
	process.exit(1);
}
process.stdout.write(JSON.stringify({ meshes, faces, vertices: seen.size, normals, uv, frontFacing, min, max }) + '\n');
