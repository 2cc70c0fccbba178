//! Range checks of a parsed case; errors name case.toml and the key.

use super::region::Region;
use super::schema::*;
use crate::error::{Error, Result};
use std::path::Path;

impl Case {
    /// Check every value's range; errors name `path` (case.toml) and the key.
    pub fn validate(&self, path: &Path) -> Result<()> {
        self.validate_inputs(path)?;
        self.validate_tissue(path)?;
        self.validate_surface_model(path)?;
        self.validate_tet(path)?;
        self.uncertainty
            .validate(self.solve.model, self.reduced_form(), path)?;
        self.validate_registration(path)?;
        self.validate_surface_regions(path)?;
        self.validate_plan(path)
    }

    /// `[[landmark]]` and `[ct]`.
    fn validate_inputs(&self, path: &Path) -> Result<()> {
        let bad = |msg: String| Err(Error::input(path, msg));
        for l in &self.landmark {
            if l.label.trim().is_empty() || l.position.iter().any(|x| !x.is_finite()) {
                return bad(format!(
                    "[[landmark]] '{}' needs a label and a finite position",
                    l.label
                ));
            }
        }
        if let Some(code) = &self.ct.axes
            && crate::volume::axes_code(code).is_none()
        {
            return bad(format!(
                "[ct] axes = \"{code}\" must be three letters, one of L/R, one of P/A and one of S/I (e.g. \"LAI\")"
            ));
        }
        if self.ct.intercept.is_some_and(|b| !b.is_finite()) {
            return bad("[ct] intercept must be finite".into());
        }
        Ok(())
    }

    /// `[tissue]` and `[tissue.stiffness]`.
    fn validate_tissue(&self, path: &Path) -> Result<()> {
        let bad = |msg: String| Err(Error::input(path, msg));
        let t = &self.tissue;
        let bounds = [t.head_threshold, t.fat_dark, t.fat_bright, t.soft, t.bone];
        if bounds.iter().any(|b| !b.is_finite()) || bounds.windows(2).any(|w| w[0] >= w[1]) {
            return bad(format!(
                "[tissue] needs head_threshold < fat_dark < fat_bright < soft < bone, got {bounds:?}"
            ));
        }
        if !(t.skin_thickness_mm > 0.0) {
            return bad("[tissue] skin_thickness_mm must be positive".into());
        }
        let s = &t.stiffness;
        if [s.skin, s.muscle, s.fat_dark, s.fat_bright]
            .iter()
            .any(|k| !(k.is_finite() && *k > 0.0))
        {
            return bad("[tissue.stiffness] values must be finite and positive".into());
        }
        Ok(())
    }

    /// The surface models' settings: `[extract]`, `[springs]`, `[surface]` and `[solve]`.
    fn validate_surface_model(&self, path: &Path) -> Result<()> {
        let bad = |msg: String| Err(Error::input(path, msg));
        let e = &self.extract;
        let ok = e.angle_step_deg > 0.0
            && e.angle_step_deg <= 30.0
            && e.z_step_mm >= 0.0
            && e.decimate_max_error_mm > 0.0;
        if !ok {
            return bad("[extract] angle_step_deg must be in (0, 30], z_step_mm >= 0, decimate_max_error_mm > 0".into());
        }
        if !(self.springs.max_length_mm > 0.0) {
            return bad("[springs] max_length_mm must be positive".into());
        }
        if !(self.surface.alpha.is_finite()
            && self.surface.alpha >= 0.0
            && self.surface.beta.is_finite()
            && self.surface.beta >= 0.0)
        {
            return bad("[surface] alpha and beta must be finite and >= 0".into());
        }
        if !(self.solve.k_c.is_finite()
            && self.solve.k_c > 0.0
            && self.solve.koch_k_c.is_finite()
            && self.solve.koch_k_c > 0.0)
        {
            return bad("[solve] k_c and koch_k_c must be finite and positive".into());
        }
        if !(self.solve.shell_mm > 0.0
            && self.solve.shell_mm.is_finite()
            && (0.0..=0.5).contains(&self.solve.shell_poisson))
        {
            return bad("[solve] shell_mm must be positive and shell_poisson in [0, 0.5]".into());
        }
        if self.solve.coarse_triangles > 0 && self.solve.coarse_triangles < 200 {
            return bad("[solve] coarse_triangles must be 0 (off) or at least 200".into());
        }
        if self.solve.steps == 0 {
            return bad("[solve] steps must be at least 1".into());
        }
        Ok(())
    }

    /// `[tet]` and its materials.
    fn validate_tet(&self, path: &Path) -> Result<()> {
        let bad = |msg: String| Err(Error::input(path, msg));
        let t = &self.tet;
        if !(t.skin_size_mm > 0.0
            && t.deep_size_mm >= t.skin_size_mm
            && t.deep_size_mm.is_finite()
            && t.margin_mm >= 0.0
            && t.margin_mm.is_finite())
        {
            return bad(
                "[tet] needs 0 < skin_size_mm <= deep_size_mm (finite) and margin_mm >= 0".into(),
            );
        }
        for (option, asked) in [
            ("degloved_maxilla", t.degloved_maxilla),
            ("degloved_chin", t.degloved_chin),
        ] {
            if let Some(why) = t.one_sided_unavailable().filter(|_| asked.required()) {
                return bad(format!(
                    "[tet] {option} = true rests the raised tissue on its bone one way, and {why} (\"auto\", the default, steps aside)"
                ));
            }
        }
        if t.material == TetMaterial::NeoHookean && t.element == TetElement::Quadratic {
            return bad(
                "[tet] material \"neo-hookean\" runs on element \"linear\" (no nonlinear 10-node tetrahedron yet)"
                    .into(),
            );
        }
        if !(t.cut_release_mm >= 0.0 && t.cut_release_mm.is_finite()) {
            return bad("[tet] cut_release_mm must be finite and >= 0".into());
        }
        if !(t.mucosa_gap_mm >= 0.0 && t.mucosa_gap_mm.is_finite()) {
            return bad("[tet] mucosa_gap_mm must be finite and >= 0".into());
        }
        if t.load_steps == 0 {
            return bad("[tet] load_steps must be at least 1".into());
        }
        for (name, m) in [
            ("skin", t.skin),
            ("muscle", t.muscle),
            ("fat_dark", t.fat_dark),
            ("fat_bright", t.fat_bright),
        ] {
            if !(m.youngs_kpa > 0.0 && m.youngs_kpa.is_finite()) {
                return bad(format!(
                    "[tet.{name}] youngs_kpa must be positive and finite"
                ));
            }
            if !(m.poisson > -1.0 && m.poisson < 0.5) {
                return bad(format!(
                    "[tet.{name}] poisson must lie in (-1, 0.5) (0.5 is incompressible: no finite bulk modulus)"
                ));
            }
        }
        Ok(())
    }

    /// `[registration]`.
    fn validate_registration(&self, path: &Path) -> Result<()> {
        let bad = |msg: String| Err(Error::input(path, msg));
        if let Some(r) = &self.registration {
            if r.scan.len() != r.ct.len() || r.scan.len() < 3 {
                return bad(format!(
                    "[registration] needs >= 3 landmark pairs, got {} scan and {} ct points",
                    r.scan.len(),
                    r.ct.len()
                ));
            }
            if r.scan.iter().chain(&r.ct).flatten().any(|x| !x.is_finite()) {
                return bad("[registration] landmarks must be finite".into());
            }
        }
        Ok(())
    }

    /// `[surface] movable` and `[[surface.region]]`.
    fn validate_surface_regions(&self, path: &Path) -> Result<()> {
        let bad = |msg: String| Err(Error::input(path, msg));
        if let Some(m) = &self.surface.movable {
            m.validate("[surface] movable")?;
        }
        for r in &self.surface.regions {
            r.shape.validate("[[surface.region]] shape")?;
            if !(r.alpha.is_finite() && r.alpha >= 0.0 && r.beta.is_finite() && r.beta >= 0.0) {
                return bad("[[surface.region]] alpha and beta must be finite and >= 0".into());
            }
            if matches!(r.shape, Region::Mask(_) | Region::Surface(_)) {
                return bad("[[surface.region]] takes box, sphere or half_space shapes".into());
            }
        }
        Ok(())
    }

    /// The plan: `[[surgery]]`, `[head]` and `[[osteotomy]]`.
    fn validate_plan(&self, path: &Path) -> Result<()> {
        let bad = |msg: String| Err(Error::input(path, msg));
        super::check_surgeries(&self.surgery).or_else(bad)?;
        if let Some(h) = &self.head
            && !(h.pitch_deg.is_finite() && h.pitch_deg.abs() <= 45.0)
        {
            return bad("[head] pitch_deg must be within ±45 degrees".into());
        }
        for o in &self.osteotomy {
            o.region.validate(&format!("osteotomy '{}'", o.name))?;
            if o.translate
                .iter()
                .chain(&o.rotate_deg)
                .chain(&o.pivot)
                .any(|x| !x.is_finite())
            {
                return bad(format!(
                    "osteotomy '{}': translate, rotate_deg and pivot must be finite",
                    o.name
                ));
            }
        }
        Ok(())
    }
}

impl Region {
    pub(super) fn validate(&self, what: &str) -> Result<()> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        let ok = match self {
            Region::Box { min, max } => {
                finite(min) && finite(max) && (0..3).all(|a| min[a] <= max[a])
            }
            Region::Sphere { center, radius } => {
                finite(center) && radius.is_finite() && *radius > 0.0
            }
            Region::HalfSpace { point, normal } => {
                finite(point) && finite(normal) && normal.iter().any(|x| *x != 0.0)
            }
            Region::Mask(_) | Region::Surface(_) => true,
        };
        if ok {
            Ok(())
        } else {
            Err(Error::config(format!(
                "case.toml: {what}: region {self:?} is empty or not finite"
            )))
        }
    }
}
