//! Soft-tissue measurements before and after (docs/guide/landmarks.md "Measurements"), in the head
//! frame's midsagittal projection (height v, anteriority a; the lateral offset dropped).

use super::frame::HeadFrame;
use super::landmark::{Carried, Ordered};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Measure {
    pub unit: String,
    pub definition: String,
    pub before: Option<f64>,
    pub after: Option<f64>,
    pub change: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub missing: Option<String>,
}

/// Soft over hard tissue movement along the anterior axis for one landmark pair.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Ratio {
    /// Anterior movement of the soft landmark (mm, + forwards).
    pub soft_mm: Option<f64>,
    /// Anterior movement of the bony landmark (mm).
    pub hard_mm: Option<f64>,
    pub ratio: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub missing: Option<String>,
}

/// The angle at b between b→a and b→c (degrees), in the (v, a) plane.
pub fn angle_deg(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    let u = [a[0] - b[0], a[1] - b[1]];
    let w = [c[0] - b[0], c[1] - b[1]];
    let cos = (u[0] * w[0] + u[1] * w[1]) / ((u[0].hypot(u[1])) * (w[0].hypot(w[1]))).max(1e-300);
    cos.clamp(-1.0, 1.0).acos().to_degrees()
}

/// Signed distance of p from the line through e1 and e2 in the (v, a) plane: + anterior.
pub fn to_line(p: [f64; 2], e1: [f64; 2], e2: [f64; 2]) -> f64 {
    let d = [e2[0] - e1[0], e2[1] - e1[1]];
    let len = d[0].hypot(d[1]).max(1e-300);
    // The unit normal with a positive anterior component.
    let mut n = [-d[1] / len, d[0] / len];
    if n[1] < 0.0 {
        n = [-n[0], -n[1]];
    }
    (p[0] - e1[0]) * n[0] + (p[1] - e1[1]) * n[1]
}

pub(crate) const PAIRS: [(&str, &str); 4] =
    [("Pog'", "Pog"), ("Ls", "A"), ("Li", "B"), ("Sn", "ANS")];

/// The displacement (mm) along the unit vector `dir` of Σ weight × landmark over `terms`
/// (one landmark, or a difference such as a lip's height), or why it cannot be measured.
pub fn along(c: &[Carried], terms: &[(&str, f64)], dir: [f64; 3]) -> Result<f64, String> {
    let mut sum = 0.0;
    for (label, w) in terms {
        let l = c
            .iter()
            .find(|l| l.label == *label)
            .ok_or_else(|| format!("{label} is not a landmark of this run"))?;
        match (l.pre, l.post) {
            (Some(a), Some(b)) => sum += w * crate::vec3::dot(crate::vec3::sub(b, a), dir),
            _ => {
                return Err(format!(
                    "{label} not found: {}",
                    l.missing.as_deref().unwrap_or("no position")
                ));
            }
        }
    }
    Ok(sum)
}

/// The measurements and soft/hard ratios of carried landmarks.
pub fn measure(c: &[Carried], frame: &HeadFrame) -> (Ordered<Measure>, Ordered<Ratio>) {
    let get = |label: &str, post: bool| -> Option<[f64; 2]> {
        let l = c.iter().find(|l| l.label == label)?;
        let p = if post { l.post } else { l.pre }?;
        let q = frame.coords(p);
        Some([q[1], q[2]])
    };
    let need = |labels: &[&str]| -> Option<String> {
        let miss: Vec<&str> = labels
            .iter()
            .copied()
            .filter(|l| get(l, false).is_none())
            .collect();
        (!miss.is_empty()).then(|| format!("needs {}, missing", miss.join(", ")))
    };
    type F = fn(&[[f64; 2]]) -> f64;
    let defs: [(&str, &str, &'static str, &[&str], F); 4] = [
        (
            "nasolabial_angle",
            "deg",
            "angle Prn–Sn–Ls at subnasale (midsagittal projection)",
            &["Prn", "Sn", "Ls"],
            |p| angle_deg(p[0], p[1], p[2]),
        ),
        (
            "mentolabial_angle",
            "deg",
            "angle Li–B'–Pog' at soft B point (midsagittal projection)",
            &["Li", "B'", "Pog'"],
            |p| angle_deg(p[0], p[1], p[2]),
        ),
        (
            "upper_lip_to_e_line",
            "mm",
            "signed distance of Ls from the E-line Prn–Pog' (+ in front of it)",
            &["Ls", "Prn", "Pog'"],
            |p| to_line(p[0], p[1], p[2]),
        ),
        (
            "lower_lip_to_e_line",
            "mm",
            "signed distance of Li from the E-line Prn–Pog' (+ in front of it)",
            &["Li", "Prn", "Pog'"],
            |p| to_line(p[0], p[1], p[2]),
        ),
    ];
    let mut out = Ordered::default();
    for (name, unit, definition, labels, f) in defs {
        let at = |post: bool| {
            labels
                .iter()
                .map(|l| get(l, post))
                .collect::<Option<Vec<[f64; 2]>>>()
                .map(|p| f(&p))
        };
        let (before, after) = (at(false), at(true));
        out.0.push((
            name.to_string(),
            Measure {
                unit: unit.into(),
                definition: definition.into(),
                before,
                after,
                change: before.zip(after).map(|(b, a)| a - b),
                missing: need(labels),
            },
        ));
    }
    // Widths between paired landmarks: the whole 3-D distance (alar width widens after a Le Fort I
    // impaction or advance, a measure the clinic follows).
    let widths: [(&str, &str, [&str; 2]); 2] = [
        (
            "alar_width",
            "distance Al-R–Al-L (the nose's width at the alae)",
            ["Al-R", "Al-L"],
        ),
        (
            "mouth_width",
            "distance Ch-R–Ch-L (the mouth's corners)",
            ["Ch-R", "Ch-L"],
        ),
    ];
    for (name, definition, [r, l]) in widths {
        let at = |post: bool| {
            let p = |label: &str| {
                let m = c.iter().find(|x| x.label == label)?;
                if post { m.post } else { m.pre }
            };
            Some(crate::vec3::norm(crate::vec3::sub(p(r)?, p(l)?)))
        };
        let (before, after) = (at(false), at(true));
        let miss: Vec<&str> = [r, l]
            .into_iter()
            .filter(|x| !c.iter().any(|m| m.label == *x && m.pre.is_some()))
            .collect();
        out.0.push((
            name.to_string(),
            Measure {
                unit: "mm".into(),
                definition: definition.into(),
                before,
                after,
                change: before.zip(after).map(|(b, a)| a - b),
                missing: (!miss.is_empty()).then(|| format!("needs {}, missing", miss.join(", "))),
            },
        ));
    }
    let mut ratios = Ordered::default();
    for (s, h) in PAIRS {
        let forward = |l: &str| -> Option<f64> {
            let (a, b) = (get(l, false)?, get(l, true)?);
            Some(b[1] - a[1])
        };
        let (soft_mm, hard_mm) = (forward(s), forward(h));
        let ratio = soft_mm
            .zip(hard_mm)
            .filter(|(_, h)| h.abs() >= 0.1)
            .map(|(s, h)| s / h);
        let missing = need(&[s, h]).or_else(|| {
            ratio
                .is_none()
                .then(|| format!("{h} moved less than 0.1 mm forwards or back"))
        });
        ratios.0.push((
            format!("{s}/{h}"),
            Ratio {
                soft_mm,
                hard_mm,
                ratio,
                missing,
            },
        ));
    }
    (out, ratios)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angle_and_line_distance_are_right_on_known_points() {
        assert!((angle_deg([0.0, 1.0], [0.0, 0.0], [1.0, 0.0]) - 90.0).abs() < 1e-12);
        assert!((angle_deg([1.0, 1.0], [0.0, 0.0], [1.0, 0.0]) - 45.0).abs() < 1e-12);
        // E-line vertical at a = 10 (from v = 0 to v = −50): a point at a = 7 is 3 mm behind.
        assert!((to_line([-20.0, 7.0], [0.0, 10.0], [-50.0, 10.0]) + 3.0).abs() < 1e-12);
        assert!((to_line([-20.0, 12.0], [-50.0, 10.0], [0.0, 10.0]) - 2.0).abs() < 1e-12);
    }

    #[test]
    fn widths_are_the_distances_between_the_paired_landmarks() {
        let lm = |label: &str, pre: Option<[f64; 3]>, post: Option<[f64; 3]>| Carried {
            label: label.into(),
            kind: super::super::Kind::Soft,
            source: super::super::Source::Detected,
            pre,
            post,
            change_mm: None,
            missing: pre.is_none().then(|| "not found".into()),
        };
        let c = [
            lm("Al-R", Some([-17.0, 0.0, 0.0]), Some([-18.0, 0.0, 0.0])),
            lm("Al-L", Some([17.0, 0.0, 0.0]), Some([18.0, 1.0, 0.0])),
            lm("Ch-R", None, None),
            lm("Ch-L", Some([25.0, 0.0, 0.0]), Some([25.0, 0.0, 0.0])),
        ];
        let frame = HeadFrame::from_plane([0.0; 3], [1.0, 0.0, 0.0], 0.0);
        let (m, _) = measure(&c, &frame);
        let get = |n: &str| &m.0.iter().find(|(k, _)| k == n).unwrap().1;
        let alar = get("alar_width");
        assert_eq!(alar.before, Some(34.0));
        assert!((alar.after.unwrap() - 36f64.hypot(1.0)).abs() < 1e-12);
        let mouth = get("mouth_width");
        assert!(mouth.before.is_none() && mouth.missing.as_deref() == Some("needs Ch-R, missing"));
    }
}
