// ply.js: the internal Gaussian PLY (Inria 3DGS / 2DGS layout, binary little-endian, as the
// services write it) into plain arrays for the viewer. 2DGS surfels have two scales; the third is
// given a thin thickness so that Spark draws them as flat discs.

const TYPES = {
  char: [1, "getInt8"], int8: [1, "getInt8"], uchar: [1, "getUint8"], uint8: [1, "getUint8"],
  short: [2, "getInt16"], int16: [2, "getInt16"], ushort: [2, "getUint16"], uint16: [2, "getUint16"],
  int: [4, "getInt32"], int32: [4, "getInt32"], uint: [4, "getUint32"], uint32: [4, "getUint32"],
  float: [4, "getFloat32"], float32: [4, "getFloat32"], double: [8, "getFloat64"], float64: [8, "getFloat64"],
};
const SH_C0 = 0.28209479177387814;

export function parseGaussianPly(buffer) {
  const bytes = new Uint8Array(buffer);
  const head = new TextDecoder().decode(bytes.subarray(0, Math.min(bytes.length, 65536)));
  const end = head.indexOf("end_header\n");
  if (!head.startsWith("ply\n") || end < 0) throw new Error("not a PLY file");
  const lines = head.slice(0, end).split("\n");
  if (!lines.includes("format binary_little_endian 1.0")) throw new Error("PLY: not binary little-endian");
  let count = -1;
  let stride = 0;
  const props = {};
  let inVertex = false;
  for (const line of lines) {
    const words = line.trim().split(/\s+/);
    if (words[0] === "element") {
      inVertex = words[1] === "vertex";
      if (inVertex) count = Number(words[2]);
    } else if (words[0] === "property" && inVertex) {
      const type = TYPES[words[1]];
      if (!type) throw new Error(`PLY: property type ${words[1]} is not supported`);
      props[words[2]] = { offset: stride, getter: type[1] };
      stride += type[0];
    }
  }
  for (const name of ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "rot_0", "rot_1", "rot_2", "rot_3"])
    if (!props[name]) throw new Error(`PLY: no ${name} property`);
  const start = end + "end_header\n".length;
  if (!(count >= 0) || start + count * stride > bytes.length) throw new Error("PLY: truncated");
  const view = new DataView(buffer, start);
  const read = (name, i) => view[props[name].getter](i * stride + props[name].offset, true);
  const n = count;
  const out = {
    count: n,
    centers: new Float32Array(3 * n),
    scales: new Float32Array(3 * n),
    quaternions: new Float32Array(4 * n), // x, y, z, w
    colors: new Float32Array(3 * n),
    opacities: new Float32Array(n),
  };
  const flat = !props.scale_2;
  for (let i = 0; i < n; ++i) {
    out.centers.set([read("x", i), read("y", i), read("z", i)], 3 * i);
    const s0 = Math.exp(read("scale_0", i));
    const s1 = Math.exp(read("scale_1", i));
    out.scales.set([s0, s1, flat ? 0.05 * Math.min(s0, s1) : Math.exp(read("scale_2", i))], 3 * i);
    const w = read("rot_0", i), x = read("rot_1", i), y = read("rot_2", i), z = read("rot_3", i);
    const norm = Math.hypot(w, x, y, z) || 1;
    out.quaternions.set([x / norm, y / norm, z / norm, w / norm], 4 * i);
    for (let c = 0; c < 3; ++c)
      out.colors[3 * i + c] = Math.min(1, Math.max(0, 0.5 + SH_C0 * read(`f_dc_${c}`, i)));
    const logit = read("opacity", i);
    out.opacities[i] = logit === Infinity ? 1 : 1 / (1 + Math.exp(-logit));
  }
  return out;
}
