//! Plans no skin can follow, refused with the place (impossible-plan errors, not numerics).

use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::osteotomy::Plan;
use crate::springs::SpringSet;
use crate::vec3::{norm, sub};

/// A plan that moves bone through the skin is impossible, whatever the tissue: after the solve,
/// no main spring may point the other way than before (skin outside its bone attachment).
pub(super) fn check_not_through_skin(
    skin: &Mesh,
    positions: &[[f64; 3]],
    springs: &SpringSet,
    plan: &Plan,
) -> Result<()> {
    let (moved, _) = plan.apply(&springs.attachments, 1.0);
    let mut flipped = 0;
    let mut worst: Option<(usize, f64)> = None;
    for s in springs
        .springs
        .iter()
        .filter(|s| s.kind == crate::springs::Kind::Main)
    {
        let pre = sub(skin.vertices[s.skin], springs.attachments[s.bone]);
        let post = sub(positions[s.skin], moved[s.bone]);
        let along = crate::vec3::dot(pre, post) / norm(pre).max(1e-12);
        if along <= 0.0 {
            flipped += 1;
            if worst.is_none_or(|(_, a)| along < a) {
                worst = Some((s.skin, along));
            }
        }
    }
    if let Some((v, along)) = worst {
        let p = skin.vertices[v];
        return Err(Error::impossible_plan(format!(
            "the bone moves through the skin at {flipped} skin vertices (worst at ({:.0}, {:.0}, {:.0}) LPS mm, {:.1} mm beyond it); check the osteotomy's translate (mm) and rotate_deg (degrees)",
            p[0], p[1], p[2], -along
        )));
    }
    Ok(())
}

/// Before solving: bone moved beyond the pre-operative skin by more than the tissue's own
/// thickness there cannot be followed by any skin (it would have to double in thickness while the
/// bone passes through it) — a plan in the wrong units or direction. Refused with the place.
pub(super) fn check_plan_reach(skin: &Mesh, springs: &SpringSet, plan: &Plan) -> Result<()> {
    let (moved, _) = plan.apply(&springs.attachments, 1.0);
    let mut count = 0;
    let mut worst: Option<(usize, f64, f64)> = None;
    for s in springs
        .springs
        .iter()
        .filter(|s| s.kind == crate::springs::Kind::Main)
    {
        let pre = sub(skin.vertices[s.skin], springs.attachments[s.bone]);
        let l = norm(pre).max(1e-12);
        // Signed distance of the moved bone point in front of the pre-operative skin.
        let beyond = -crate::vec3::dot(pre, sub(skin.vertices[s.skin], moved[s.bone])) / l;
        if beyond > l {
            count += 1;
            if worst.is_none_or(|(_, b, _)| beyond > b) {
                worst = Some((s.skin, beyond, l));
            }
        }
    }
    if let Some((v, beyond, l)) = worst {
        let p = skin.vertices[v];
        return Err(Error::impossible_plan(format!(
            "the bone moves through the skin at {count} skin vertices (worst at ({:.0}, {:.0}, {:.0}) LPS mm: {beyond:.1} mm beyond the skin, where the soft tissue is {l:.1} mm thick); check the osteotomy's translate (mm), rotate_deg (degrees) and direction (LPS: −y is anterior)",
            p[0], p[1], p[2]
        )));
    }
    Ok(())
}
