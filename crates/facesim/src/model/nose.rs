//! The external nose as one framework (`[tet] nose_youngs_kpa`, docs/validation-notes.md "A
//! structural candidate: the nasal framework"). The nose keeps its shape by cartilage (septal
//! cartilage 2–6 MPa) hinged on the nasal bones; meshed as soft tissue (10–30 kPa) it follows the
//! maxilla wholesale. With the option, the tetrahedra of the external nose take one effective
//! modulus.
//!
//! The region, in the head frame of the pre-operative landmarks: between the alae (half the alar
//! width either side of pronasale, 17 mm without alare), from `[tet] nose_base_above_sn_mm`
//! (2.5 mm by default: the columella's base and the lip below stay tissue) above subnasale to
//! [`BELOW_N_MM`] below soft nasion, in front of the piriform aperture (the anterior nasal
//! spine's depth, else the alar creases', else 15 mm behind subnasale) — less every tetrahedron
//! with a corner on bone the plan moves. In a Le Fort I down-fracture the septum is freed from
//! the maxillary crest and the nasal mucosa raised off the nasal floor, so the framework stays
//! hinged on the fixed nasal bones and is not carried by the segment; a region reaching back to
//! the maxilla's front (a coarse CT without the spine: 15 mm behind subnasale lies in the bone
//! on headsq) would otherwise make a stiff block of the tissue bonded to the moving bone.

use crate::case::TissueElastic;
use crate::error::{Error, Result};
use crate::landmarks::{HeadFrame, Landmark};

/// The nose's root ends this far below soft nasion (mm): the nasal bones hold the framework
/// there.
const BELOW_N_MM: f64 = 7.0;
/// The anterior nasal spine's depth behind subnasale where neither it nor the alae are found
/// (mm): the upper lip's thickness at its base, about 15 mm in adults (Holdaway 1983, "basic
/// upper lip thickness"); on the real CT 15.5, on the phantoms 10–17.
const SN_TO_ANS_MM: f64 = 15.0;
/// Half the nose's width without alare (mm; adult alar width 31–38 mm, Farkas 1994).
const HALF_WIDTH_MM: f64 = 17.0;

/// The material of a nose tetrahedron of `tissue`: the nose's modulus with its tissue's Poisson's
/// ratio (the solve's materials and the reduced model's nose terms alike).
pub(crate) fn material(tissue: TissueElastic, youngs_kpa: f64) -> TissueElastic {
    TissueElastic {
        youngs_kpa,
        ..tissue
    }
}

/// Per tetrahedron: whether its centroid lies in the external nose the pre-operative head frame
/// and landmarks locate (`Scene::landmarks_pre`: the skin's, the skull's for the anterior nasal
/// spine, and the case's own over the detected ones). Missing landmarks are an error naming
/// them: the option asks for a nose the landmarks must find. `moved_bone`, per node: on bone
/// the plan moves; a tetrahedron touching it stays tissue. The framework's base lies
/// `above_sn_mm` above subnasale.
pub(crate) fn nose_tets(
    (frame, lms): (Option<HeadFrame>, Vec<Landmark>),
    above_sn_mm: f64,
    nodes: &[[f64; 3]],
    tets: &[[u32; 4]],
    moved_bone: &[bool],
) -> Result<Vec<bool>> {
    let missing = |why: String| {
        Error::config(format!(
            "[tet] nose_youngs_kpa: the nose's region needs {why}; give it as a [[landmark]] in case.toml"
        ))
    };
    let frame = frame.ok_or_else(|| missing("a head frame (the skin is empty)".into()))?;
    let at = |label: &str| -> Result<[f64; 3]> {
        let l: Option<&Landmark> = lms.iter().find(|l| l.label == label);
        l.and_then(|l| l.position)
            .map(|p| frame.coords(p))
            .ok_or_else(|| {
                missing(format!(
                    "{label}, which was not found ({})",
                    l.and_then(|l| l.missing.clone()).unwrap_or_default()
                ))
            })
    };
    let (prn, sn, n) = (at("Prn")?, at("Sn")?, at("N'")?);
    let alae = match (at("Al-R"), at("Al-L")) {
        (Ok(r), Ok(l)) => Some((r, l)),
        _ => None,
    };
    let half = alae.map_or(HALF_WIDTH_MM, |(r, l)| 0.5 * (l[0] - r[0]).abs());
    // The piriform aperture's depth: the anterior nasal spine's, else the alar creases' (on the
    // real CT within 1 mm of it; a coarse CT's spine is often not found), else subnasale's less
    // the soft tissue's thickness there.
    let back = match (at("ANS"), alae) {
        (Ok(ans), _) => ans[2],
        (Err(_), Some((r, l))) => 0.5 * (r[2] + l[2]),
        (Err(_), None) => sn[2] - SN_TO_ANS_MM,
    };
    let (bottom, top) = (sn[1] + above_sn_mm, n[1] - BELOW_N_MM);
    Ok(tets
        .iter()
        .map(|t| {
            let c: [f64; 3] =
                std::array::from_fn(|k| t.iter().map(|i| nodes[*i as usize][k]).sum::<f64>() / 4.0);
            let [s, v, a] = frame.coords(c);
            (s - prn[0]).abs() <= half
                && v >= bottom
                && v <= top
                && a >= back
                && !t.iter().any(|i| moved_bone[*i as usize])
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::landmarks::{Kind, Source};

    fn found(label: &str, p: [f64; 3]) -> Landmark {
        Landmark {
            label: label.into(),
            kind: Kind::Soft,
            position: Some(p),
            source: Source::Detected,
            missing: None,
        }
    }

    /// One small tetrahedron per centroid.
    fn tets_at(centres: &[[f64; 3]]) -> (Vec<[f64; 3]>, Vec<[u32; 4]>) {
        let mut nodes = Vec::new();
        let mut tets = Vec::new();
        for c in centres {
            let k = nodes.len() as u32;
            let corners = [
                [1.0, 0.0, 0.0],
                [-1.0, 1.0, 0.0],
                [-1.0, -1.0, 0.5],
                [1.0, 0.0, -0.5],
            ];
            let mean: [f64; 3] =
                std::array::from_fn(|a| corners.iter().map(|p| p[a]).sum::<f64>() / 4.0);
            nodes.extend(corners.map(|p| std::array::from_fn(|a| c[a] + p[a] - mean[a])));
            tets.push([k, k + 1, k + 2, k + 3]);
        }
        (nodes, tets)
    }

    /// `[tet] nose_base_above_sn_mm`'s default.
    const BASE: f64 = 2.5;

    /// An upright head (anterior = −y) with the nose's landmarks: subnasale at depth 85 and
    /// height 0, the tip 10 mm above it, soft nasion at 50.
    fn upright_nose() -> (HeadFrame, Vec<Landmark>) {
        let frame = HeadFrame::from_plane([0.0; 3], [1.0, 0.0, 0.0], 0.0);
        let lms = vec![
            found("Prn", [0.0, -100.0, 10.0]),
            found("Sn", [0.0, -85.0, 0.0]),
            found("N'", [0.0, -90.0, 50.0]),
        ];
        (frame, lms)
    }

    #[test]
    fn without_the_spine_or_the_alae_the_nose_ends_15_mm_behind_subnasale() {
        // Subnasale at depth 85, so the nose reaches back to 70.
        let (frame, lms) = upright_nose();
        // In front of 70, just behind it, beside the nose, below its base.
        let (nodes, tets) = tets_at(&[
            [0.0, -72.0, 20.0],
            [0.0, -68.0, 20.0],
            [20.0, -90.0, 20.0],
            [0.0, -90.0, 1.0],
        ]);
        let still = vec![false; nodes.len()];
        let inside = nose_tets((Some(frame), lms.clone()), BASE, &nodes, &tets, &still).unwrap();
        assert_eq!(inside, [true, false, false, false]);
        // A corner on bone the plan moves keeps the tetrahedron tissue.
        let mut moved = still.clone();
        moved[2] = true;
        let inside = nose_tets((Some(frame), lms.clone()), BASE, &nodes, &tets, &moved).unwrap();
        assert_eq!(inside, [false, false, false, false]);
        // A found spine sets the depth instead.
        let mut with_ans = lms;
        with_ans.push(found("ANS", [0.0, -75.0, 2.0]));
        let inside = nose_tets((Some(frame), with_ans), BASE, &nodes, &tets, &still).unwrap();
        assert_eq!(inside, [false, false, false, false]);
        // Subnasale itself cannot be done without.
        let err = nose_tets(
            (Some(frame), vec![found("Prn", [0.0, -100.0, 10.0])]),
            BASE,
            &nodes,
            &tets,
            &still,
        )
        .unwrap_err();
        assert!(err.to_string().contains("Sn"), "{err}");
    }

    #[test]
    fn the_framework_starts_at_its_base_above_subnasale() {
        let (frame, lms) = upright_nose();
        // The columella 6 mm above subnasale, the tip lobule at 20 mm, the lip 1 mm above it.
        let (nodes, tets) = tets_at(&[[0.0, -86.0, 6.0], [0.0, -90.0, 20.0], [0.0, -86.0, 1.0]]);
        let still = vec![false; nodes.len()];
        let at = |base: f64| nose_tets((Some(frame), lms.clone()), base, &nodes, &tets, &still);
        assert_eq!(at(BASE).unwrap(), [true, true, false]);
        assert_eq!(at(10.0).unwrap(), [false, true, false]);
        assert_eq!(at(0.0).unwrap(), [true, true, true]);
    }
}
