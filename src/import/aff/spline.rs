//! Kochanek–Bartels (tension, continuity, bias) splines as BART evaluates them.
//!
//! * Positions and scales: one cubic Hermite polynomial per pair of consecutive keys
//!   `(k[i+1], k[i+2])`, with the outgoing tangent at `k[i+1]` and the incoming tangent at
//!   `k[i+2]` built from the TCB parameters and adjusted for uneven key spacing
//!   (`2·(t2−t1)/(t2−t0)` and `2·(t2−t1)/(t3−t1)`). The parameter `u` runs linearly in time
//!   over the segment.
//! * Rotations: axis–angle keys turned into unit quaternions, consecutive ones brought
//!   into the same hemisphere, then the quaternion analogue (tangents in the logarithm
//!   space, evaluated by `squad`).
//! * The first and last keys only shape the end tangents: before the second key the value
//!   is the second key's, after the next-to-last key the next-to-last key's. A spline
//!   needs at least four keys.
//!
//! Evaluation is in `f64`.

use glam::{DQuat, DVec3, DVec4};

/// Tension, continuity, bias of one key.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Tcb {
    pub tension: f64,
    pub continuity: f64,
    pub bias: f64,
}

/// A key of a translation or scale track.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VecKey {
    pub time: f64,
    pub value: DVec3,
    pub tcb: Tcb,
}

/// A key of a rotation track: an absolute rotation of `angle` radians about `axis`
/// (normalised on use; a zero axis is the identity).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RotKey {
    pub time: f64,
    pub axis: DVec3,
    pub angle: f64,
    pub tcb: Tcb,
}

/// The smallest number of keys a spline track needs.
pub const MIN_KEYS: usize = 4;

/// Which polynomial (`0..n-3`) covers `t`, and the parameter `u` in `[0, 1]` on it.
/// Clamps before the second key and after the next-to-last one. `times.len() >= 4`.
fn segment(times: &[f64], t: f64) -> (usize, f64) {
    let polys = times.len() - 3;
    let tmin = |i: usize| times[i + 1];
    let tmax = |i: usize| times[i + 2];
    if t <= tmin(0) {
        return (0, 0.0);
    }
    if t >= tmax(polys - 1) {
        return (polys - 1, 1.0);
    }
    let i = (0..polys).find(|&i| t < tmax(i)).unwrap_or(polys - 1);
    let range = tmax(i) - tmin(i);
    let u = if range > 0.0 {
        (t - tmin(i)) / range
    } else {
        0.0
    };
    (i, u.clamp(0.0, 1.0))
}

/// `2·(t2−t1)/(t_far−t_near)`, or 1 where the keys coincide.
fn adjust(t1: f64, t2: f64, near: f64, far: f64) -> f64 {
    let d = far - near;
    if d > 0.0 {
        2.0 * (t2 - t1) / d
    } else {
        1.0
    }
}

/// Multipliers of the outgoing tangent at key `k1` (`(out0, out1)`: weights of the
/// incoming difference and of the segment's difference).
fn out_multipliers(k1: Tcb, adj: f64) -> (f64, f64) {
    let omt = 1.0 - k1.tension;
    let out0 = 0.5 * adj * omt * (1.0 + k1.continuity) * (1.0 + k1.bias);
    let out1 = 0.5 * adj * omt * (1.0 - k1.continuity) * (1.0 - k1.bias);
    (out0, out1)
}

/// Multipliers of the incoming tangent at key `k2` (`(in0, in1)`: weights of the
/// segment's difference and of the outgoing difference).
fn in_multipliers(k2: Tcb, adj: f64) -> (f64, f64) {
    let omt = 1.0 - k2.tension;
    let in0 = 0.5 * adj * omt * (1.0 - k2.continuity) * (1.0 + k2.bias);
    let in1 = 0.5 * adj * omt * (1.0 + k2.continuity) * (1.0 - k2.bias);
    (in0, in1)
}

/// The TCB spline through `keys` at time `t`. `None` with fewer than four keys.
pub fn eval_vec(keys: &[VecKey], t: f64) -> Option<DVec3> {
    if keys.len() < MIN_KEYS {
        return None;
    }
    let times: Vec<f64> = keys.iter().map(|k| k.time).collect();
    let (i, u) = segment(&times, t);
    let [k0, k1, k2, k3] = [keys[i], keys[i + 1], keys[i + 2], keys[i + 3]];
    let dp = k2.value - k1.value;
    let (out0, out1) = out_multipliers(k1.tcb, adjust(k1.time, k2.time, k0.time, k2.time));
    let t_out = out1 * dp + out0 * (k1.value - k0.value);
    let (in0, in1) = in_multipliers(k2.tcb, adjust(k1.time, k2.time, k1.time, k3.time));
    let t_in = in1 * (k3.value - k2.value) + in0 * dp;
    let c0 = k1.value;
    let c1 = t_out;
    let c2 = 3.0 * dp - 2.0 * t_out - t_in;
    let c3 = -2.0 * dp + t_out + t_in;
    Some(c0 + u * (c1 + u * (c2 + u * c3)))
}

/// The unit quaternion of an axis–angle key (identity for a zero axis).
pub fn key_quat(axis: DVec3, angle: f64) -> DQuat {
    let len = axis.length();
    if len.is_nan() || len <= 0.0 || !len.is_finite() {
        return DQuat::IDENTITY;
    }
    let a = axis / len;
    let (s, c) = (0.5 * angle).sin_cos();
    DQuat::from_xyzw(a.x * s, a.y * s, a.z * s, c)
}

fn v4(q: DQuat) -> DVec4 {
    DVec4::new(q.x, q.y, q.z, q.w)
}

fn q4(v: DVec4) -> DQuat {
    DQuat::from_xyzw(v.x, v.y, v.z, v.w)
}

const EPS: f64 = 1e-6;

/// Logarithm of a unit quaternion: `(θ·axis, 0)`.
fn log(q: DQuat) -> DVec4 {
    let v = DVec3::new(q.x, q.y, q.z);
    if q.w.abs() < 1.0 {
        let theta = q.w.acos();
        let s = theta.sin();
        if s.abs() >= EPS {
            return (v * (theta / s)).extend(0.0);
        }
    }
    v.extend(0.0)
}

/// Exponential of a pure quaternion `(v, 0)`.
fn exp(p: DVec4) -> DQuat {
    let v = p.truncate();
    let theta = v.length();
    let s = theta.sin();
    let scaled = if s.abs() >= EPS { v * (s / theta) } else { v };
    DQuat::from_xyzw(scaled.x, scaled.y, scaled.z, theta.cos())
}

/// Spherical interpolation without choosing the shorter arc (as the reference does: the
/// keys were already put in one hemisphere).
fn slerp(t: f64, p: DVec4, q: DVec4) -> DVec4 {
    let cos = p.dot(q).clamp(-1.0, 1.0);
    let angle = cos.acos();
    if angle.abs() < EPS {
        return p;
    }
    let s = angle.sin();
    if s.abs() < EPS {
        return p;
    }
    (p * ((1.0 - t) * angle).sin() + q * (t * angle).sin()) / s
}

fn squad(t: f64, p: DVec4, a: DVec4, b: DVec4, q: DVec4) -> DVec4 {
    slerp(2.0 * t * (1.0 - t), slerp(t, p, q), slerp(t, a, b))
}

/// The key quaternions, each of keys `2..=n-2` negated where needed so that it lies in
/// the hemisphere of its predecessor.
pub fn aligned_quats(keys: &[RotKey]) -> Vec<DQuat> {
    let mut q: Vec<DQuat> = keys.iter().map(|k| key_quat(k.axis, k.angle)).collect();
    let n = q.len();
    for i in 2..n.saturating_sub(1) {
        if q[i - 1].dot(q[i]) < 0.0 {
            q[i] = -q[i];
        }
    }
    q
}

/// The rotation spline through `keys` at time `t` (unit quaternion). `None` with fewer
/// than four keys.
pub fn eval_rot(keys: &[RotKey], t: f64) -> Option<DQuat> {
    if keys.len() < MIN_KEYS {
        return None;
    }
    let times: Vec<f64> = keys.iter().map(|k| k.time).collect();
    let (i, u) = segment(&times, t);
    let quats = aligned_quats(keys);
    let [q0, q1, q2, q3] = [quats[i], quats[i + 1], quats[i + 2], quats[i + 3]];
    let [k0, k1, k2, k3] = [keys[i], keys[i + 1], keys[i + 2], keys[i + 3]];

    let logdq = log(q1.conjugate() * q2);
    let (out0, out1) = out_multipliers(k1.tcb, adjust(k1.time, k2.time, k0.time, k2.time));
    let t_out = logdq * out1 + log(q0.conjugate() * q1) * out0;
    let (in0, in1) = in_multipliers(k2.tcb, adjust(k1.time, k2.time, k1.time, k3.time));
    let t_in = logdq * in0 + log(q2.conjugate() * q3) * in1;

    let a = q1 * exp((t_out - logdq) * 0.5);
    let b = q2 * exp((logdq - t_in) * 0.5);
    let r = squad(u, v4(q1), v4(a), v4(b), v4(q2));
    let len = r.length();
    Some(if len > 0.0 && len.is_finite() {
        q4(r / len)
    } else {
        q1
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vk(time: f64, x: f64) -> VecKey {
        VecKey {
            time,
            value: DVec3::new(x, 0.0, 0.0),
            tcb: Tcb::default(),
        }
    }

    #[test]
    fn clamps_outside_the_inner_keys_and_passes_through_keys() {
        let keys = [vk(0.0, 5.0), vk(1.0, 1.0), vk(2.0, 3.0), vk(3.0, 7.0)];
        assert_eq!(eval_vec(&keys, -10.0).unwrap().x, 1.0);
        assert_eq!(eval_vec(&keys, 1.0).unwrap().x, 1.0);
        assert!((eval_vec(&keys, 2.0).unwrap().x - 3.0).abs() < 1e-12);
        assert!((eval_vec(&keys, 9.0).unwrap().x - 3.0).abs() < 1e-12);
        assert!(eval_vec(&keys[..3], 1.0).is_none());
    }

    #[test]
    fn constant_rotation_stays_put() {
        let k = |t| RotKey {
            time: t,
            axis: DVec3::Y,
            angle: 1.0,
            tcb: Tcb::default(),
        };
        let keys = [k(0.0), k(1.0), k(2.0), k(3.0)];
        let q = eval_rot(&keys, 1.5).unwrap();
        assert!(q.angle_between(DQuat::from_axis_angle(DVec3::Y, 1.0)) < 1e-9);
    }
}
