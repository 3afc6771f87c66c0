//! Frame and angle math of the task: quaternion rotations, projected gravity, yaw and heading.
//! Quaternions are `(w, x, y, z)`, rotating base-frame vectors into the world frame.

/// Rotates world vector `v` into the frame of unit quaternion `q = (w, x, y, z)`: `R(q)ᵀ v`.
#[inline]
pub fn quat_rotate_inverse(q: [f32; 4], v: [f32; 3]) -> [f32; 3] {
    let (w, x, y, z) = (q[0], -q[1], -q[2], -q[3]);
    // t = 2 (u × v), v' = v + w t + u × t, with u = (x, y, z) of the conjugate
    let t = [
        2.0 * (y * v[2] - z * v[1]),
        2.0 * (z * v[0] - x * v[2]),
        2.0 * (x * v[1] - y * v[0]),
    ];
    [
        v[0] + w * t[0] + (y * t[2] - z * t[1]),
        v[1] + w * t[1] + (z * t[0] - x * t[2]),
        v[2] + w * t[2] + (x * t[1] - y * t[0]),
    ]
}

/// Gravity direction `(0, 0, −1)` in the base frame of `q`.
#[inline]
pub fn projected_gravity(q: [f32; 4]) -> [f32; 3] {
    quat_rotate_inverse(q, [0.0, 0.0, -1.0])
}

/// Yaw (heading) of `q`: the angle of the rotated base x axis in the world xy plane
/// (IsaacLab `heading_w`).
#[inline]
pub fn yaw_of(q: [f32; 4]) -> f32 {
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// Wraps an angle to `[−π, π)`.
#[inline]
pub fn wrap_to_pi(a: f32) -> f32 {
    use std::f32::consts::PI;
    let r = (a + PI).rem_euclid(2.0 * PI) - PI;
    if r.is_finite() { r } else { 0.0 }
}

/// Heading-mode yaw-rate command: `clip(stiffness · wrap(target − yaw), lo, hi)`.
#[inline]
pub fn heading_yaw_rate(target: f32, yaw: f32, stiffness: f32, range: [f32; 2]) -> f32 {
    (stiffness * wrap_to_pi(target - yaw)).clamp(range[0], range[1])
}

/// Quaternion `(w, x, y, z)` of a rotation by `yaw` about z.
pub fn quat_from_yaw(yaw: f32) -> [f32; 4] {
    let (s, c) = (0.5 * yaw).sin_cos();
    [c, 0.0, 0.0, s]
}

/// Quaternion of a rotation by `yaw` about z followed (in the body frame) by a small roll and pitch
/// (rad): `q_yaw ⊗ normalise(1, roll/2, pitch/2, 0)`, exact to first order in the tilt angles.
pub fn quat_from_yaw_and_tilt(yaw: f32, roll: f32, pitch: f32) -> [f32; 4] {
    let q = quat_from_yaw(yaw);
    let t = [1.0, 0.5 * roll, 0.5 * pitch, 0.0];
    let mut m = [
        q[0] * t[0] - q[1] * t[1] - q[2] * t[2] - q[3] * t[3],
        q[0] * t[1] + q[1] * t[0] + q[2] * t[3] - q[3] * t[2],
        q[0] * t[2] - q[1] * t[3] + q[2] * t[0] + q[3] * t[1],
        q[0] * t[3] + q[1] * t[2] - q[2] * t[1] + q[3] * t[0],
    ];
    let n = m.iter().map(|v| v * v).sum::<f32>().sqrt();
    m.iter_mut().for_each(|v| *v /= n);
    m
}
