//! What `[[surgery]]` entries (docs/guide/planning.md) can be told wrong at load, before the CT is
//! read: one entry of each kind, `autorotate` on a Le Fort I without a BSSO, moves within the
//! limits a plan in millimetres and degrees keeps.

use super::schema::{Pivot, Surgery, SurgeryKind};

/// The largest translation (mm) and rotation (degrees) a surgery may state.
pub const MAX_MOVE_MM: f64 = 20.0;
pub const MAX_TURN_DEG: f64 = 30.0;

impl SurgeryKind {
    /// The kind as case.toml writes it.
    pub fn key(self) -> &'static str {
        match self {
            SurgeryKind::LeFortI => "le-fort-i",
            SurgeryKind::Bsso => "bsso",
            SurgeryKind::Genioplasty => "genioplasty",
        }
    }
}

/// Err: one line naming the entry (1-based) and the problem.
pub fn check_surgeries(surgeries: &[Surgery]) -> Result<(), String> {
    let count = |k: SurgeryKind| surgeries.iter().filter(|s| s.kind == k).count();
    for k in [
        SurgeryKind::LeFortI,
        SurgeryKind::Bsso,
        SurgeryKind::Genioplasty,
    ] {
        if count(k) > 1 {
            return Err(format!(
                "[[surgery]]: {} appears {} times; one of each kind",
                k.key(),
                count(k)
            ));
        }
    }
    if surgeries.iter().any(|s| s.autorotate) && count(SurgeryKind::Bsso) > 0 {
        return Err(
            "[[surgery]]: autorotate with a bsso: the bsso places the mandible; drop one".into(),
        );
    }
    for (i, s) in surgeries.iter().enumerate() {
        let at = |e: String| format!("[[surgery]] {} ({}): {e}", i + 1, s.kind.key());
        if s.autorotate && s.kind != SurgeryKind::LeFortI {
            return Err(at("autorotate applies to a le-fort-i".into()));
        }
        check_size(s).map_err(at)?;
        if let Some(Pivot::Point(p)) = &s.pivot
            && p.iter().any(|x| !x.is_finite())
        {
            return Err(at("its pivot point must be finite".into()));
        }
    }
    Ok(())
}

/// A stated move within the limits, finite.
fn check_size(s: &Surgery) -> Result<(), String> {
    let t = [s.advance_mm, s.up_mm, s.left_mm];
    let a = [s.pitch_deg, s.roll_deg, s.yaw_deg];
    if t.iter().chain(&a).any(|v| !v.is_finite()) {
        return Err("its moves must be finite numbers".into());
    }
    let len = t.iter().map(|x| x * x).sum::<f64>().sqrt();
    if len > MAX_MOVE_MM {
        return Err(format!(
            "it moves the segment {len:.1} mm, more than {MAX_MOVE_MM} mm: check the units (mm) and the signs"
        ));
    }
    if let Some(x) = a.iter().find(|x| x.abs() > MAX_TURN_DEG) {
        return Err(format!(
            "it turns the segment {x} degrees, more than {MAX_TURN_DEG}: check the units (degrees)"
        ));
    }
    Ok(())
}
