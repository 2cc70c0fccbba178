//! Moves in the clinical head frame, and their LPS osteotomy (docs/guide/planning.md "Signs").
//!
//! Translations: `advance` along the frame's anterior axis, `up` along its vertical, `left`
//! toward the patient's left. Rotations, each right-handed about a frame axis through the
//! pivot:
//! - `pitch` about the left axis: positive turns the front down (clockwise seen from the
//!   patient's right, the surgeon's "clockwise" of the occlusal plane);
//! - `roll` about the anterior axis: positive raises the patient's left side;
//! - `yaw` about the vertical axis: positive turns the front toward the patient's left.
//!
//! Order: pitch, then roll, then yaw (R = R_yaw · R_roll · R_pitch), then the translation:
//! p' = R (p − pivot) + pivot + t.

use crate::landmarks::HeadFrame;
use crate::vec3::{add, dot, scale};

/// Six moves in the head frame: advance, up, left (mm); pitch, roll, yaw (degrees).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Moves {
    pub advance_mm: f64,
    pub up_mm: f64,
    pub left_mm: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
    pub yaw_deg: f64,
}

type M3 = [[f64; 3]; 3];

fn mul(a: M3, b: M3) -> M3 {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    r
}

fn transpose(a: M3) -> M3 {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = a[j][i];
        }
    }
    r
}

/// The right-handed rotation by `deg` about the unit axis `u` (Rodrigues).
pub(crate) fn about_axis(u: [f64; 3], deg: f64) -> M3 {
    let (s, c) = deg.to_radians().sin_cos();
    let k = [[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]];
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let kk: f64 = (0..3).map(|m| k[i][m] * k[m][j]).sum();
            r[i][j] = if i == j { 1.0 } else { 0.0 } + s * k[i][j] + (1.0 - c) * kk;
        }
    }
    r
}

/// The columns of the frame: left, up, anterior (LPS).
fn basis(frame: &HeadFrame) -> M3 {
    let (l, v, a) = (frame.lateral, frame.vertical, frame.anterior);
    [[l[0], v[0], a[0]], [l[1], v[1], a[1]], [l[2], v[2], a[2]]]
}

/// The LPS rotation of the moves' pitch, roll and yaw.
pub fn rotation(frame: &HeadFrame, m: &Moves) -> M3 {
    let pitch = about_axis(frame.lateral, m.pitch_deg);
    let roll = about_axis(frame.anterior, m.roll_deg);
    let yaw = about_axis(frame.vertical, m.yaw_deg);
    mul(yaw, mul(roll, pitch))
}

/// The LPS translation of the moves.
pub fn translation(frame: &HeadFrame, m: &Moves) -> [f64; 3] {
    add(
        scale(frame.anterior, m.advance_mm),
        add(
            scale(frame.vertical, m.up_mm),
            scale(frame.lateral, m.left_mm),
        ),
    )
}

/// `rotate_deg` of an osteotomy (R = Rz·Ry·Rx about LPS axes, `crate::osteotomy::rotation`)
/// equal to the rotation `r`; exact away from a 90° turn about y, which a plan of ≤ 30° never
/// reaches.
pub(crate) fn lps_angles(r: M3) -> [f64; 3] {
    let b = (-r[2][0]).clamp(-1.0, 1.0).asin();
    let a = r[2][1].atan2(r[2][2]);
    let c = r[1][0].atan2(r[0][0]);
    [a.to_degrees(), b.to_degrees(), c.to_degrees()]
}

/// The moves of a rigid transform p' = R (p − pivot) + pivot + t, read in the head frame.
pub(crate) fn read_back(frame: &HeadFrame, r: M3, t: [f64; 3]) -> Moves {
    // R in the frame's basis: Ry(yaw) Rz(roll) Rx(pitch) with x left, y up, z anterior.
    let f = basis(frame);
    let m = mul(transpose(f), mul(r, f));
    Moves {
        advance_mm: dot(t, frame.anterior),
        up_mm: dot(t, frame.vertical),
        left_mm: dot(t, frame.lateral),
        pitch_deg: (-m[1][2]).atan2(m[1][1]).to_degrees(),
        roll_deg: m[1][0].clamp(-1.0, 1.0).asin().to_degrees(),
        yaw_deg: (-m[2][0]).atan2(m[0][0]).to_degrees(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pitched_frame() -> HeadFrame {
        crate::anatomy::bone::turned(
            &HeadFrame::with_up(
                [10.0, -80.0, 5.0],
                {
                    let v = [1.0, 0.05, -0.02];
                    scale(v, 1.0 / crate::vec3::norm(v))
                },
                [0.0, 0.0, 1.0],
                0.0,
            ),
            16.0,
        )
    }

    #[test]
    fn positive_pitch_turns_the_front_down_roll_lifts_the_left_yaw_turns_the_front_left() {
        let f = pitched_frame();
        let turn = |m: Moves, v: [f64; 3]| {
            let r = rotation(&f, &m);
            [0, 1, 2].map(|i| (0..3).map(|k| r[i][k] * v[k]).sum::<f64>())
        };
        let pitch = Moves {
            pitch_deg: 10.0,
            ..Moves::default()
        };
        assert!(dot(turn(pitch, f.anterior), f.vertical) < -0.17);
        let roll = Moves {
            roll_deg: 10.0,
            ..Moves::default()
        };
        assert!(dot(turn(roll, f.lateral), f.vertical) > 0.17);
        let yaw = Moves {
            yaw_deg: 10.0,
            ..Moves::default()
        };
        assert!(dot(turn(yaw, f.anterior), f.lateral) > 0.17);
    }

    #[test]
    fn the_lps_angles_rebuild_the_rotation_and_the_moves_read_back() {
        let f = pitched_frame();
        for m in [
            Moves {
                advance_mm: 5.0,
                up_mm: 2.0,
                left_mm: -1.0,
                pitch_deg: 3.0,
                roll_deg: -2.0,
                yaw_deg: 1.5,
            },
            Moves {
                pitch_deg: -25.0,
                roll_deg: 12.0,
                yaw_deg: -29.0,
                ..Moves::default()
            },
        ] {
            let r = rotation(&f, &m);
            let back = crate::osteotomy::rotation(lps_angles(r));
            for i in 0..3 {
                for j in 0..3 {
                    assert!((r[i][j] - back[i][j]).abs() < 1e-12, "{r:?} vs {back:?}");
                }
            }
            let got = read_back(&f, r, translation(&f, &m));
            for (a, b) in [
                (got.advance_mm, m.advance_mm),
                (got.up_mm, m.up_mm),
                (got.left_mm, m.left_mm),
                (got.pitch_deg, m.pitch_deg),
                (got.roll_deg, m.roll_deg),
                (got.yaw_deg, m.yaw_deg),
            ] {
                assert!((a - b).abs() < 1e-9, "{got:?} vs {m:?}");
            }
        }
    }
}
