// The pose maths of the page, in float64 (plain arrays), the same as darthand's (tools/darthand/model/anatomy.py,
// bones.py, export/correctives.py). Matrices are row-major 3x3 arrays [[r0], [r1], [r2]] acting on column vectors.
//
//   R_local = R_bend R_spread R_twist        (rotations about the joint frame's z, y, x axes)
//   R_i     = F_i R_local F_i^T              (MANO's rotation of joint i; F_i's columns: twist, spread, bend axes)
//   L_i     = O_parent^T R_i O_i             (the glTF joint node's local rotation; O_i the bone's rest frame)
//   channel pose_<joint>_r<r><c> = (R_i - I)[r][c];  shape weight = clip(value / scale, 0, 1)

export const NUM_JOINTS = 16;

export function mul(a, b) {
  const out = [[0, 0, 0], [0, 0, 0], [0, 0, 0]];
  for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) {
    out[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
  }
  return out;
}

export function transpose(a) {
  return [[a[0][0], a[1][0], a[2][0]], [a[0][1], a[1][1], a[2][1]], [a[0][2], a[1][2], a[2][2]]];
}

const IDENTITY = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];

/** R_bend R_spread R_twist of angles [twist, spread, bend] in radians (scipy's intrinsic "ZYX" Euler). */
export function localRotation([twist, spread, bend]) {
  const [ct, st, cs, ss, cb, sb] = [Math.cos(twist), Math.sin(twist), Math.cos(spread), Math.sin(spread),
    Math.cos(bend), Math.sin(bend)];
  const rz = [[cb, -sb, 0], [sb, cb, 0], [0, 0, 1]];
  const ry = [[cs, 0, ss], [0, 1, 0], [-ss, 0, cs]];
  const rx = [[1, 0, 0], [0, ct, -st], [0, st, ct]];
  return mul(rz, mul(ry, rx));
}

/** [twist, spread, bend] radians of a local rotation (the inverse of localRotation for |spread| < 90 deg). */
export function localAngles(r) {
  return [Math.atan2(r[2][1], r[2][2]), Math.asin(Math.max(-1, Math.min(1, -r[2][0]))), Math.atan2(r[1][0], r[0][0])];
}

/** MANO rotations R_i (16 matrices) of joint angles in degrees (16 x [twist, spread, bend]). */
export function manoRotations(rig, anglesDeg) {
  return anglesDeg.map((a, i) => {
    const F = rig.joint_frames[i];
    return mul(F, mul(localRotation(a.map((x) => x * Math.PI / 180)), transpose(F)));
  });
}

/** Joint angles in degrees of MANO rotations (the inverse of manoRotations). */
export function anglesOf(rig, rotations) {
  return rotations.map((R, i) => {
    const F = rig.joint_frames[i];
    return localAngles(mul(transpose(F), mul(R, F))).map((x) => x * 180 / Math.PI);
  });
}

/** The glTF joint nodes' local rotations L_i = O_parent^T R_i O_i as quaternions [x, y, z, w]. */
export function nodeQuaternions(rig, rotations) {
  return rotations.map((R, i) => {
    const p = rig.parents[i];
    const Op = p < 0 ? IDENTITY : rig.bone_frames[p];
    return quaternionOf(mul(transpose(Op), mul(R, rig.bone_frames[i])));
  });
}

/** Unit quaternion [x, y, z, w] of a rotation matrix (Shepperd's method: the largest of w, x, y, z first). */
export function quaternionOf(m) {
  const tr = m[0][0] + m[1][1] + m[2][2];
  let q;
  if (tr > 0) {
    const s = 2 * Math.sqrt(tr + 1);
    q = [(m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, 0.25 * s];
  } else if (m[0][0] > m[1][1] && m[0][0] > m[2][2]) {
    const s = 2 * Math.sqrt(1 + m[0][0] - m[1][1] - m[2][2]);
    q = [0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s, (m[2][1] - m[1][2]) / s];
  } else if (m[1][1] > m[2][2]) {
    const s = 2 * Math.sqrt(1 + m[1][1] - m[0][0] - m[2][2]);
    q = [(m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s, (m[0][2] - m[2][0]) / s];
  } else {
    const s = 2 * Math.sqrt(1 + m[2][2] - m[0][0] - m[1][1]);
    q = [(m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s, (m[1][0] - m[0][1]) / s];
  }
  const n = Math.hypot(...q);
  return q.map((x) => x / n);
}

/** Rotation matrix of a unit quaternion [x, y, z, w]. */
export function matrixOf([x, y, z, w]) {
  return [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
    [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
    [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]];
}

/** MANO axis-angle vector (48 numbers, radians) of the rotations. */
export function axisAngles(rotations) {
  const out = [];
  for (const R of rotations) {
    const [x, y, z, w] = quaternionOf(R);
    const s = Math.hypot(x, y, z);
    const angle = 2 * Math.atan2(s, w);
    const k = s < 1e-12 ? 2 : angle / s;       // angle / sin(angle / 2) -> 2 as the angle -> 0
    out.push(x * k, y * k, z * k);
  }
  return out;
}

/** Per-joint quaternion slerp of two sets of rotations along the shortest arc (t = 0 gives a). */
export function slerpRotations(a, b, t) {
  return a.map((Ra, i) => {
    const qa = quaternionOf(Ra);
    let qb = quaternionOf(b[i]);
    let dot = qa[0] * qb[0] + qa[1] * qb[1] + qa[2] * qb[2] + qa[3] * qb[3];
    if (dot < 0) { qb = qb.map((x) => -x); dot = -dot; }
    const omega = Math.acos(Math.min(1, dot));
    let wa = 1 - t, wb = t;
    if (omega > 1e-6) { wa = Math.sin((1 - t) * omega) / Math.sin(omega); wb = Math.sin(t * omega) / Math.sin(omega); }
    const q = qa.map((x, k) => wa * x + wb * qb[k]);
    const n = Math.hypot(...q);
    return matrixOf(q.map((x) => x / n));
  });
}

/**
 * The corrective blend shapes' weights for MANO rotations, from the package's table
 * (asset.extras.darthand.blend_shapes.shapes: [{name, channel, scale}], channel `pose_<joint>_r<r><c>`):
 * returns a Float32Array in the table's order.
 */
export function correctiveWeights(rig, table, rotations) {
  const out = new Float32Array(table.length);
  table.forEach((shape, k) => {
    const c = shape._parsed || (shape._parsed = parseChannel(rig, shape.channel));
    if (!c) return;
    const value = rotations[c.joint][c.r][c.c] - (c.r === c.c ? 1 : 0);
    out[k] = Math.min(1, Math.max(0, value / shape.scale));
  });
  return out;
}

function parseChannel(rig, channel) {
  const m = /^pose_([a-z]+[0-9])_r([0-2])([0-2])$/.exec(channel);
  if (!m) return null;
  const joint = rig.joints.indexOf(m[1]);
  return joint < 0 ? null : { joint, r: +m[2], c: +m[3] };
}

/** Angles clamped into the joint limits (degrees). */
export function clampAngles(rig, anglesDeg) {
  return anglesDeg.map((a, j) => a.map((x, k) => Math.min(rig.limits_deg[j][k][1], Math.max(rig.limits_deg[j][k][0], x))));
}

export function zeroAngles() {
  return Array.from({ length: NUM_JOINTS }, () => [0, 0, 0]);
}
