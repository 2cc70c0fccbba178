//! The plan basis (docs/design/plan-basis.md): per segment s and entry k of M = [R − I | t′] (row-major,
//! k = 4·row + column, column 3 = t′), the face displacement B_{s,k} when segment s's bone moves
//! by the unit matrix E_k and the other segments stay. A plan's face displacement is
//! B_0 + Σ_s Σ_k m_{s,k} B_{s,k} (B_0 = 0 without loads).

use crate::case::{Osteotomy, Region};
use crate::error::{Error, Result};

/// Entries of M per segment.
pub const COLUMNS: usize = 12;

/// The basis of one run (LPS mm).
#[derive(Clone, Debug)]
pub struct PlanBasis {
    /// "tet-linear", "tet-neo-hookean-linearised" or "c1-linearised".
    pub model: String,
    /// True when a plan's prediction equals a full run of that plan (up to rounding): a linear
    /// model whose moved bone follows the plan's matrices. False: a linear preview.
    pub exact: bool,
    /// Why the basis is not exact, or other limits (one line each).
    pub warnings: Vec<String>,
    pub segments: Vec<SegmentBasis>,
    /// The pre-operative face (face_pre's vertices, in order) and its triangles.
    pub face_pre: Vec<[f64; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// The plan the run solved (case.toml's `[[osteotomy]]`, in order).
    pub run_plan: Vec<Osteotomy>,
    /// B_0, the face displacement with no bone move, when not zero.
    pub offset: Option<Vec<[f64; 3]>>,
    /// The facesim version that built the basis.
    pub facesim_version: String,
    /// The largest distance (mm) between the basis's face for the run's own plan and the run's
    /// face: rounding for an exact basis, the linearisation's error at that plan otherwise.
    pub run_plan_error_mm: f64,
}

/// One segment's columns.
#[derive(Clone, Debug)]
pub struct SegmentBasis {
    pub name: String,
    pub region: Region,
    /// The run's pivot (LPS mm), the default for the page's sliders.
    pub pivot: [f64; 3],
    /// `COLUMNS` face displacement fields (mm per unit entry), each one per face vertex.
    pub columns: Vec<Vec<[f64; 3]>>,
}

/// M = [R − I | t′] of a segment's move, row-major: R = Rz·Ry·Rx (degrees),
/// t′ = (I − R)·pivot + translate, so that the bone displacement is M·[x; 1].
pub fn matrix(o: &Osteotomy) -> [f64; COLUMNS] {
    let r = crate::osteotomy::rotation(o.rotate_deg);
    let mut m = [0.0; COLUMNS];
    for i in 0..3 {
        let rp: f64 = (0..3).map(|j| r[i][j] * o.pivot[j]).sum();
        for j in 0..3 {
            m[4 * i + j] = r[i][j] - if i == j { 1.0 } else { 0.0 };
        }
        m[4 * i + 3] = o.pivot[i] - rp + o.translate[i];
    }
    m
}

/// M·[x; 1]: the displacement of the point `x` under the move with matrix `m`.
pub(crate) fn displace(m: &[f64; COLUMNS], x: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| {
        m[4 * i] * x[0] + m[4 * i + 1] * x[1] + m[4 * i + 2] * x[2] + m[4 * i + 3]
    })
}

/// The unit matrix E_k.
pub fn unit(k: usize) -> [f64; COLUMNS] {
    std::array::from_fn(|j| if j == k { 1.0 } else { 0.0 })
}

/// Regions compare by their case.toml form; a mask or a surface by its file (the same file
/// named by two paths, e.g. relative to the case and to a plan elsewhere, is the same).
pub(crate) fn same_region(a: &Region, b: &Region) -> bool {
    let file = |r: &Region| match r {
        Region::Mask(m) => Some(m.path.clone()),
        Region::Surface(s) => Some(s.path.clone()),
        _ => None,
    };
    if let (Some(x), Some(y)) = (file(a), file(b))
        && std::mem::discriminant(a) == std::mem::discriminant(b)
        && let (Ok(x), Ok(y)) = (x.canonicalize(), y.canonicalize())
    {
        return x == y;
    }
    match (serde_json::to_value(a), serde_json::to_value(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

impl PlanBasis {
    /// Each segment's M for `plan` (a segment the plan leaves out does not move: M = 0). A plan
    /// entry naming no segment of the run, changing a segment's region or naming one twice is an
    /// error (Error::Config; the caller names the plan's file).
    pub fn matrices(&self, plan: &[Osteotomy]) -> Result<Vec<[f64; COLUMNS]>> {
        let mut ms = vec![[0.0; COLUMNS]; self.segments.len()];
        let mut seen = vec![false; self.segments.len()];
        let names = || {
            self.segments
                .iter()
                .map(|s| format!("'{}'", s.name))
                .collect::<Vec<_>>()
                .join(", ")
        };
        for o in plan {
            let Some(s) = self.segments.iter().position(|s| s.name == o.name) else {
                return Err(Error::config(format!(
                    "osteotomy '{}' is not a segment of the run (its segments: {})",
                    o.name,
                    names()
                )));
            };
            if seen[s] {
                return Err(Error::config(format!(
                    "osteotomy '{}' appears twice",
                    o.name
                )));
            }
            if !same_region(&o.region, &self.segments[s].region) {
                return Err(Error::config(format!(
                    "osteotomy '{}': its region differs from the run's (a new region needs a new run)",
                    o.name
                )));
            }
            if o.translate
                .iter()
                .chain(&o.rotate_deg)
                .chain(&o.pivot)
                .any(|v| !v.is_finite())
            {
                return Err(Error::config(format!(
                    "osteotomy '{}': translate, rotate_deg and pivot must be finite",
                    o.name
                )));
            }
            seen[s] = true;
            ms[s] = matrix(o);
        }
        Ok(ms)
    }

    /// The face displacement (mm, per face_pre vertex) for segment matrices `ms`.
    pub(crate) fn displacement_of(&self, ms: &[[f64; COLUMNS]]) -> Vec<[f64; 3]> {
        let n = self.face_pre.len();
        let mut out = self.offset.clone().unwrap_or_else(|| vec![[0.0; 3]; n]);
        // One axpy per non-zero entry: streaming passes over columns that fit in cache.
        for (seg, m) in self.segments.iter().zip(ms) {
            for (col, &w) in seg.columns.iter().zip(m) {
                if w == 0.0 {
                    continue;
                }
                for (o, c) in out.iter_mut().zip(col) {
                    o[0] += w * c[0];
                    o[1] += w * c[1];
                    o[2] += w * c[2];
                }
            }
        }
        out
    }

    /// The face displacement for `plan` (see [`PlanBasis::matrices`]).
    pub fn displacement(&self, plan: &[Osteotomy]) -> Result<Vec<[f64; 3]>> {
        Ok(self.displacement_of(&self.matrices(plan)?))
    }

    /// The predicted face vertices (LPS mm, face_pre order) for `plan`.
    pub fn predict(&self, plan: &[Osteotomy]) -> Result<Vec<[f64; 3]>> {
        let d = self.displacement(plan)?;
        Ok(self
            .face_pre
            .iter()
            .zip(d)
            .map(|(p, d)| [p[0] + d[0], p[1] + d[1], p[2] + d[2]])
            .collect())
    }

    /// The segment whose name is `name`.
    pub fn segment(&self, name: &str) -> Option<&SegmentBasis> {
        self.segments.iter().find(|s| s.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::osteotomy::Plan;

    fn osteotomy(translate: [f64; 3], rotate_deg: [f64; 3], pivot: [f64; 3]) -> Osteotomy {
        Osteotomy {
            name: "m".into(),
            region: Region::Sphere {
                center: [0.0; 3],
                radius: 1e9,
            },
            translate,
            rotate_deg,
            pivot,
        }
    }

    #[test]
    fn the_matrix_reproduces_the_plans_rigid_move() {
        // The plan applies R (p − pivot) + pivot + translate; M·[p; 1] must be its displacement.
        let o = osteotomy([1.5, -2.0, 0.25], [7.0, -13.0, 29.0], [10.0, -4.0, 33.0]);
        let pts = [[0.0, 0.0, 0.0], [12.0, -7.5, 40.0], [-30.0, 55.0, -2.0]];
        let (moved, _) = Plan::new(std::slice::from_ref(&o)).apply(&pts, 1.0);
        let m = matrix(&o);
        for (p, q) in pts.iter().zip(&moved) {
            let d = displace(&m, *p);
            for c in 0..3 {
                assert!((p[c] + d[c] - q[c]).abs() < 1e-12, "{p:?}: {d:?} vs {q:?}");
            }
        }
        // No move: M = 0.
        assert_eq!(
            matrix(&osteotomy([0.0; 3], [0.0; 3], [5.0, 6.0, 7.0])),
            [0.0; 12]
        );
    }

    #[test]
    fn a_plan_is_the_weighted_sum_of_columns_and_bad_plans_are_refused() {
        let o = osteotomy([1.0, 2.0, 3.0], [0.0; 3], [0.0; 3]);
        let columns: Vec<Vec<[f64; 3]>> = (0..COLUMNS)
            .map(|k| vec![[k as f64, 0.0, 1.0], [0.0, 1.0, 0.0]])
            .collect();
        let b = PlanBasis {
            model: "tet-linear".into(),
            exact: true,
            warnings: vec![],
            segments: vec![SegmentBasis {
                name: "m".into(),
                region: o.region.clone(),
                pivot: [0.0; 3],
                columns,
            }],
            face_pre: vec![[0.0; 3], [1.0, 1.0, 1.0]],
            triangles: vec![],
            run_plan: vec![o.clone()],
            offset: None,
            facesim_version: "0".into(),
            run_plan_error_mm: 0.0,
        };
        // t′ = (1, 2, 3) sits in entries 3, 7, 11.
        let d = b.displacement(std::slice::from_ref(&o)).unwrap();
        assert_eq!(d[0], [3.0 + 2.0 * 7.0 + 3.0 * 11.0, 0.0, 6.0]);
        assert_eq!(b.predict(&[]).unwrap()[1], [1.0, 1.0, 1.0]);
        let mut other = o.clone();
        other.name = "x".into();
        assert!(b.predict(&[other]).unwrap_err().to_string().contains("'x'"));
        let mut moved = o.clone();
        moved.region = Region::Sphere {
            center: [0.0; 3],
            radius: 1.0,
        };
        assert!(
            b.predict(&[moved])
                .unwrap_err()
                .to_string()
                .contains("region")
        );
        assert!(b.predict(&[o.clone(), o]).is_err());
    }
}
