//! CalculiX (`ccx`, Debian's calculix-ccx, installed by scripts/test-setup.sh) as an independent
//! engine for the volumetric model (docs/design/crosscheck.md): the same nodes, tetrahedra, materials,
//! prescribed displacements and nodal forces written as a CalculiX input deck, solved by `ccx` in
//! a scratch directory, and the nodal displacements and forces read back from its .dat file.
//!
//! Deck facts used (CalculiX CrunchiX User's Manual, v2.20): node and element numbers start at 1;
//! C3D4 is the linear tetrahedron (one integration point, the same stiffness as facesim's
//! element), C3D10 the quadratic one (corners, then mid-edge nodes of edges 1-2, 2-3, 3-1, 1-4,
//! 2-4, 3-4: VTK's order); `*BOUNDARY` lines are `node, first dof, last dof, value`; `*CLOAD`
//! lines `node, dof, value`; `*DLOAD` lines `element, Pk, pressure` for face k of a tetrahedron
//! (1: corners 1-2-3, 2: 1-4-2, 3: 2-4-3, 4: 3-4-1), a positive pressure pushing into it; `*ELASTIC` takes E, ν; `*HYPERELASTIC, NEO HOOKE` takes C10, D1
//! for U = C10 (Ī1 − 3) + (J − 1)² / D1 (manual eq. 485), so μ = 2 C10 and K = 2 / D1; with
//! NLGEOM the prescribed values are ramped over the step. `*NODE PRINT` writes 7 significant
//! digits; [`solve_precise`] removes that limit for linear steps by one refinement pass.
//! The solver is SPOOLES (direct), named in the deck so the comparison is not against an
//! iterative solver's tolerance.

use facesim::error::{Error, NumericalKind, Result};
use facesim::tet::vtu::Cells;
use facesim::tet::{TetMesh, TissueElastic};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A material as CalculiX knows it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Material {
    /// Small-strain isotropic elasticity (`*ELASTIC`): E (kPa), ν.
    Linear { youngs_kpa: f64, poisson: f64 },
    /// Compressible neo-Hooke (`*HYPERELASTIC, NEO HOOKE`): U = C10 (Ī1 − 3) + (J − 1)² / D1.
    NeoHooke { c10: f64, d1: f64 },
}

impl Material {
    pub fn linear(e: TissueElastic) -> Self {
        Material::Linear {
            youngs_kpa: e.youngs_kpa,
            poisson: e.poisson,
        }
    }

    /// The neo-Hookean material with the same small-strain shear and bulk moduli as `e`:
    /// C10 = μ / 2, D1 = 2 / K with K = E / (3 (1 − 2ν)).
    pub fn neo_hooke(e: TissueElastic) -> Self {
        let (_, mu) = e.lame();
        let bulk = e.youngs_kpa / (3.0 * (1.0 - 2.0 * e.poisson));
        Material::NeoHooke {
            c10: mu / 2.0,
            d1: 2.0 / bulk,
        }
    }

    fn key(&self) -> [u64; 3] {
        match *self {
            Material::Linear {
                youngs_kpa,
                poisson,
            } => [0, youngs_kpa.to_bits(), poisson.to_bits()],
            Material::NeoHooke { c10, d1 } => [1, c10.to_bits(), d1.to_bits()],
        }
    }
}

/// One displacement component of one node: held at `value` (mm) or loaded by `value` (N).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dof {
    pub node: u32,
    /// 0, 1, 2 for x, y, z.
    pub axis: usize,
    pub value: f64,
}

/// The analysis step: small-strain linear (`nlgeom = false`, one increment) or geometrically
/// nonlinear with the load ramped over `increments` equal increments (CalculiX may cut one
/// back when it does not converge).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Step {
    pub nlgeom: bool,
    pub increments: u32,
}

impl Step {
    pub const LINEAR: Step = Step {
        nlgeom: false,
        increments: 1,
    };
}

/// A uniform pressure (kPa) on the face of cell `cell` whose corners are `corners` (any order):
/// positive pushes into the cell, as facesim's `Loads::pressure` on a boundary face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pressure {
    pub cell: u32,
    pub corners: [u32; 3],
    pub value: f64,
}

/// A problem for CalculiX: one material per cell, held and loaded components, face pressures.
#[derive(Clone, Copy, Debug)]
pub struct Problem<'a> {
    pub nodes: &'a [[f64; 3]],
    pub cells: Cells<'a>,
    pub material: &'a [Material],
    pub held: &'a [Dof],
    pub loads: &'a [Dof],
    pub pressure: &'a [Pressure],
    pub step: Step,
}

/// CalculiX's number (1–4) of the face of a tetrahedron with corners `cell` (its first four
/// nodes) that has the corners `face`.
fn face_number(cell: &[u32], face: [u32; 3]) -> Option<usize> {
    const FACES: [[usize; 3]; 4] = [[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]];
    let mut want = face;
    want.sort_unstable();
    FACES
        .iter()
        .position(|f| {
            let mut have = f.map(|i| cell[i]);
            have.sort_unstable();
            have == want
        })
        .map(|k| k + 1)
}

/// What CalculiX printed at the end of the step, per node: displacement (mm) and the nodal
/// force `RF` (the internal force: the reaction at held components, the applied load at free
/// ones once in equilibrium).
#[derive(Clone, Debug)]
pub struct Solution {
    pub displacement: Vec<[f64; 3]>,
    pub force: Vec<[f64; 3]>,
}

/// Linear materials of a facesim mesh, one per tetrahedron.
pub fn materials(mesh: &TetMesh) -> Vec<Material> {
    mesh.material.iter().map(|m| Material::linear(*m)).collect()
}

/// max |a − b| ÷ max |b| over the components of the nodes where `keep` holds (the difference
/// itself where b is zero there): how far one engine's displacement is from the other's.
pub fn relative_difference(a: &[[f64; 3]], b: &[[f64; 3]], keep: impl Fn(usize) -> bool) -> f64 {
    let (mut diff, mut size) = (0.0_f64, 0.0_f64);
    for i in (0..a.len()).filter(|&i| keep(i)) {
        for c in 0..3 {
            diff = diff.max((a[i][c] - b[i][c]).abs());
            size = size.max(b[i][c].abs());
        }
    }
    if size > 0.0 { diff / size } else { diff }
}

/// Linear materials from per-cell Young's moduli (kPa) and Poisson ratios, as tets.vtu holds them.
pub fn linear_materials(youngs_kpa: &[f64], poisson: &[f64]) -> Vec<Material> {
    youngs_kpa
        .iter()
        .zip(poisson)
        .map(|(&youngs_kpa, &poisson)| Material::Linear {
            youngs_kpa,
            poisson,
        })
        .collect()
}

/// Every component of the prescribed nodes (facesim's `solve_linear` convention) as held dofs.
pub fn held_nodes(prescribed: &[Option<[f64; 3]>]) -> Vec<Dof> {
    prescribed
        .iter()
        .enumerate()
        .filter_map(|(n, p)| p.map(|u| (n, u)))
        .flat_map(|(n, u)| {
            (0..3).map(move |axis| Dof {
                node: n as u32,
                axis,
                value: u[axis],
            })
        })
        .collect()
}

/// The input deck. Numbers are written by `num`, in at most the 20 characters CalculiX reads.
pub fn deck(p: &Problem) -> Result<String> {
    let (n, c) = (p.nodes.len(), p.cells.len());
    if p.material.len() != c {
        return Err(Error::config(format!(
            "CalculiX deck: {} materials for {c} cells",
            p.material.len()
        )));
    }
    if let Some(d) = p
        .held
        .iter()
        .chain(p.loads)
        .find(|d| d.node as usize >= n || d.axis > 2 || !d.value.is_finite())
    {
        return Err(Error::config(format!(
            "CalculiX deck: bad dof {d:?} ({n} nodes)"
        )));
    }
    if let Some(i) = (0..c).find(|&i| p.cells.cell(i).iter().any(|&k| k as usize >= n)) {
        return Err(Error::config(format!(
            "CalculiX deck: cell {i} names a node beyond {n}"
        )));
    }
    let mut faces = Vec::with_capacity(p.pressure.len());
    for pr in p.pressure {
        let k = ((pr.cell as usize) < c)
            .then(|| face_number(p.cells.cell(pr.cell as usize), pr.corners))
            .flatten()
            .filter(|_| pr.value.is_finite())
            .ok_or_else(|| Error::config(format!("CalculiX deck: bad pressure {pr:?}")))?;
        faces.push((pr.cell + 1, k, pr.value));
    }
    if p.step.increments == 0 {
        return Err(Error::config("CalculiX deck: a step needs increments >= 1"));
    }
    // Writing to a String cannot fail.
    let mut s = String::new();
    let _ = writeln!(s, "*HEADING\nfacesim cross-check\n*NODE, NSET=NALL");
    for (i, x) in p.nodes.iter().enumerate() {
        let _ = writeln!(s, "{}, {}, {}, {}", i + 1, num(x[0]), num(x[1]), num(x[2]));
    }
    // One element set per distinct material, in order of first use.
    let mut distinct: Vec<(Material, Vec<usize>)> = Vec::new();
    for (i, m) in p.material.iter().enumerate() {
        match distinct.iter_mut().find(|(d, _)| d.key() == m.key()) {
            Some((_, cells)) => cells.push(i),
            None => distinct.push((*m, vec![i])),
        }
    }
    let kind = match p.cells {
        Cells::Linear(_) => "C3D4",
        Cells::Quadratic(_) => "C3D10",
    };
    for (k, (_, cells)) in distinct.iter().enumerate() {
        let _ = writeln!(s, "*ELEMENT, TYPE={kind}, ELSET=E{}", k + 1);
        for &i in cells {
            let _ = write!(s, "{}", i + 1);
            for v in p.cells.cell(i) {
                let _ = write!(s, ", {}", v + 1);
            }
            s.push('\n');
        }
    }
    for (k, (m, _)) in distinct.iter().enumerate() {
        let _ = writeln!(s, "*MATERIAL, NAME=M{}", k + 1);
        match *m {
            Material::Linear {
                youngs_kpa,
                poisson,
            } => {
                let _ = writeln!(s, "*ELASTIC\n{}, {}", num(youngs_kpa), num(poisson));
            }
            Material::NeoHooke { c10, d1 } => {
                let _ = writeln!(s, "*HYPERELASTIC, NEO HOOKE\n{}, {}", num(c10), num(d1));
            }
        }
        let _ = writeln!(s, "*SOLID SECTION, ELSET=E{0}, MATERIAL=M{0}", k + 1);
    }
    let step = &p.step;
    if step.nlgeom {
        let dt = 1.0 / step.increments as f64;
        let _ = writeln!(
            s,
            "*STEP, NLGEOM, INC={}\n*STATIC, SOLVER=SPOOLES\n{}, 1.0, {}, {}",
            (10 * step.increments).max(100),
            num(dt),
            num(dt * 1e-3),
            num(dt)
        );
    } else {
        let _ = writeln!(s, "*STEP\n*STATIC, SOLVER=SPOOLES");
    }
    if !p.held.is_empty() {
        s.push_str("*BOUNDARY\n");
        for d in p.held {
            let _ = writeln!(
                s,
                "{}, {}, {}, {}",
                d.node + 1,
                d.axis + 1,
                d.axis + 1,
                num(d.value)
            );
        }
    }
    if !p.loads.is_empty() {
        s.push_str("*CLOAD\n");
        for d in p.loads {
            let _ = writeln!(s, "{}, {}, {}", d.node + 1, d.axis + 1, num(d.value));
        }
    }
    if !faces.is_empty() {
        s.push_str("*DLOAD\n");
        for (cell, k, value) in faces {
            let _ = writeln!(s, "{cell}, P{k}, {}", num(value));
        }
    }
    s.push_str("*NODE PRINT, NSET=NALL\nU, RF\n*END STEP\n");
    Ok(s)
}

/// A number for a deck field: CalculiX reads at most 20 characters per field, so the shortest
/// round-trip form when it fits, else 14 significant digits (relative rounding ≤ 5e-14); below
/// 1e-99 in magnitude, zero (a 3-digit exponent does not fit beside 14 digits).
fn num(x: f64) -> String {
    let s = format!("{x:e}");
    if s.len() <= 20 {
        return s;
    }
    if x.abs() < 1e-99 {
        return "0.".into();
    }
    (0..14)
        .rev()
        .map(|p| format!("{x:.p$e}"))
        .find(|s| s.len() <= 20)
        .unwrap_or_else(|| "0.".into())
}

/// Solve with CalculiX: displacements and nodal forces to the 7 digits `*NODE PRINT` writes.
pub fn solve(p: &Problem) -> Result<Solution> {
    run(&deck(p)?, p.nodes.len())
}

/// A linear step solved to full precision: CalculiX's printed answer u₁ (7 digits), then the
/// residual r = f − K u₁ (CalculiX's nodal forces with every component held at u₁) and the
/// correction K δ = r with the held components at zero, all by CalculiX; u₁ + δ. One pass of
/// iterative refinement: the printing error shrinks from ~5e-7 to ~5e-7 of itself. With nodal
/// loads, r at a loaded node is the load minus a force printed to 7 digits, which bounds the
/// gain (to ~5e-7 of the loads' share of u). Pressures are refused: CalculiX does not print
/// their nodal forces, which r needs.
pub fn solve_precise(p: &Problem) -> Result<Solution> {
    if p.step.nlgeom {
        return Err(Error::config(
            "CalculiX refinement applies to linear steps only (NLGEOM set)",
        ));
    }
    if !p.pressure.is_empty() {
        return Err(Error::config(
            "CalculiX refinement needs nodal loads only (pressure given)",
        ));
    }
    let first = solve(p)?;
    let n = p.nodes.len();
    // u₁ with the held components at their exact values.
    let mut u1 = first.displacement;
    let mut held = vec![false; 3 * n];
    for d in p.held {
        u1[d.node as usize][d.axis] = d.value;
        held[3 * d.node as usize + d.axis] = true;
    }
    let all: Vec<Dof> = (0..3 * n)
        .map(|i| Dof {
            node: (i / 3) as u32,
            axis: i % 3,
            value: u1[i / 3][i % 3],
        })
        .collect();
    let internal = solve(&Problem {
        held: &all,
        loads: &[],
        ..*p
    })?
    .force;
    let mut f = vec![0.0; 3 * n];
    for d in p.loads {
        f[3 * d.node as usize + d.axis] += d.value;
    }
    let residual: Vec<Dof> = (0..3 * n)
        .filter(|&i| !held[i])
        .map(|i| Dof {
            node: (i / 3) as u32,
            axis: i % 3,
            value: f[i] - internal[i / 3][i % 3],
        })
        .collect();
    let zero: Vec<Dof> = p.held.iter().map(|d| Dof { value: 0.0, ..*d }).collect();
    let correction = solve(&Problem {
        held: &zero,
        loads: &residual,
        ..*p
    })?;
    let displacement = (0..n)
        .map(|v| std::array::from_fn(|c| u1[v][c] + correction.displacement[v][c]))
        .collect();
    Ok(Solution {
        displacement,
        force: first.force,
    })
}

/// Run `ccx` on a deck in a scratch directory (removed on success, kept and named on failure),
/// on one thread: the tests' machine is shared, and the answer should not depend on scheduling.
pub fn run(deck: &str, nodes: usize) -> Result<Solution> {
    run_timed(deck, nodes, 1).map(|(solution, _)| solution)
}

/// What one `ccx` run cost: wall-clock seconds of the process (input read, assembly, SPOOLES
/// factor and solve, output written) and the CPU seconds it used, user + system.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunCost {
    pub wall_s: f64,
    pub cpu_s: f64,
}

/// [`run`] on `threads` threads (`OMP_NUM_THREADS` and `CCX_NPROC_EQUATION_SOLVER`, the
/// variables CalculiX reads), with what the run cost. The CPU time is that of waited-for
/// children (`getrusage(RUSAGE_CHILDREN)`) before and after, so it is exact only when no other
/// child of this process ends meanwhile.
pub fn run_timed(deck: &str, nodes: usize, threads: usize) -> Result<(Solution, RunCost)> {
    static COUNTER: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let k = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("facesim-ccx-{}-{k}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| Error::output(&dir, e))?;
    let inp = dir.join("job.inp");
    std::fs::write(&inp, deck).map_err(|e| Error::output(&inp, e))?;
    let threads = threads.max(1).to_string();
    let cpu_before = children_cpu_s();
    let start = std::time::Instant::now();
    let out = std::process::Command::new("ccx")
        .args(["-i", "job"])
        .current_dir(&dir)
        .env("OMP_NUM_THREADS", &threads)
        .env("CCX_NPROC_EQUATION_SOLVER", &threads)
        .output()
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => {
                Error::config("CalculiX (ccx) not found: run scripts/test-setup.sh")
            }
            _ => Error::config(format!("CalculiX (ccx) could not be started: {e}")),
        })?;
    let cost = RunCost {
        wall_s: start.elapsed().as_secs_f64(),
        cpu_s: children_cpu_s() - cpu_before,
    };
    let log = String::from_utf8_lossy(&out.stdout);
    // ccx reports errors on stdout; its exit status is not always non-zero.
    if let Some(line) = log
        .lines()
        .find(|l| l.contains("*ERROR"))
        .or((!out.status.success()).then_some("non-zero exit status"))
    {
        return Err(failure(&dir, line.trim()));
    }
    let dat = dir.join("job.dat");
    let text = std::fs::read_to_string(&dat).map_err(|e| Error::input(&dat, e))?;
    let solution = parse_dat(&text, nodes).map_err(|m| Error::input(&dat, m))?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok((solution, cost))
}

/// User + system CPU seconds of every child this process has waited for.
pub fn children_cpu_s() -> f64 {
    // SAFETY: getrusage writes one rusage struct, which is zero-initialised here.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut u) } != 0 {
        return f64::NAN;
    }
    let s = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    s(u.ru_utime) + s(u.ru_stime)
}

fn failure(dir: &Path, line: &str) -> Error {
    // The kind is not structured in ccx's output; every failure is reported as not converged,
    // with the deck kept for a look.
    let kept: PathBuf = dir.join("job.inp");
    Error::numerical(
        NumericalKind::NotConverged,
        format!("CalculiX failed ({line}); deck kept at {}", kept.display()),
    )
}

/// The last `displacements` and `forces` blocks of a .dat file (the end of the step).
pub fn parse_dat(text: &str, nodes: usize) -> std::result::Result<Solution, String> {
    let block = |title: &str| -> std::result::Result<Vec<[f64; 3]>, String> {
        let start = text
            .rfind(&format!(" {title} ("))
            .ok_or_else(|| format!("no {title} block"))?;
        let mut v = vec![[f64::NAN; 3]; nodes];
        let mut seen = 0;
        // The block's title line, a blank line, then one line per node until a blank line.
        for line in text[start..].lines().skip(2) {
            let f: Vec<&str> = line.split_whitespace().collect();
            if f.is_empty() {
                break;
            }
            let node: usize = f[0]
                .parse()
                .map_err(|_| format!("bad line in {title}: {line}"))?;
            if f.len() != 4 || node == 0 || node > nodes {
                return Err(format!("bad line in {title}: {line}"));
            }
            for c in 0..3 {
                v[node - 1][c] = f[c + 1]
                    .parse()
                    .map_err(|_| format!("bad number in {title}: {line}"))?;
            }
            seen += 1;
        }
        if seen != nodes {
            return Err(format!("{title} for {seen} of {nodes} nodes"));
        }
        Ok(v)
    };
    Ok(Solution {
        displacement: block("displacements")?,
        force: block("forces")?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deck_numbers_fit_calculix_fields() {
        for x in [
            0.1 + 0.2,
            -2.2499999999999998e-1,
            -1.0 / 3.0,
            1e-300,
            -7.3e200,
            2.5,
        ] {
            let s = num(x);
            let back: f64 = s.parse().unwrap();
            assert!(s.len() <= 20, "{s}");
            assert!((back - x).abs() <= 5e-14 * x.abs() + 1e-99, "{x} -> {s}");
        }
        assert_eq!(num(2.5), "2.5e0");
    }

    #[test]
    fn pressure_faces_are_named_by_their_corners_in_any_order() {
        let cell = [10, 11, 12, 13];
        assert_eq!(face_number(&cell, [12, 11, 10]), Some(1));
        assert_eq!(face_number(&cell, [13, 10, 11]), Some(2));
        assert_eq!(face_number(&cell, [11, 13, 12]), Some(3));
        assert_eq!(face_number(&cell, [12, 13, 10]), Some(4));
        assert_eq!(face_number(&cell, [10, 11, 14]), None);
        let nodes = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let bad = Pressure {
            cell: 0,
            corners: [0, 1, 2],
            value: f64::NAN,
        };
        let p = Problem {
            nodes: &nodes,
            cells: Cells::Linear(&[[0, 1, 2, 3]]),
            material: &[Material::NeoHooke { c10: 1.0, d1: 0.1 }],
            held: &[],
            loads: &[],
            pressure: &[Pressure { value: 0.5, ..bad }],
            step: Step::LINEAR,
        };
        assert!(deck(&p).unwrap().contains("*DLOAD\n1, P1, 5e-1\n"));
        for wrong in [
            bad,
            Pressure { cell: 1, ..bad },
            Pressure {
                corners: [0, 1, 1],
                value: 1.0,
                ..bad
            },
        ] {
            let e = deck(&Problem {
                pressure: &[wrong],
                ..p
            })
            .unwrap_err()
            .to_string();
            assert!(e.contains("bad pressure"), "{e}");
        }
    }

    #[test]
    fn a_dat_file_is_parsed_by_node_number() {
        let dat = " displacements (vx,vy,vz) for set NALL and time  0.5000000E+00\n\n         2  1.000000E+00  0.000000E+00  0.000000E+00\n         1  9.000000E+00  0.000000E+00  0.000000E+00\n\n displacements (vx,vy,vz) for set NALL and time  0.1000000E+01\n\n         2  2.000000E+00  0.000000E+00 -1.500000E-03\n         1  0.000000E+00  3.000000E+00  0.000000E+00\n\n forces (fx,fy,fz) for set NALL and time  0.1000000E+01\n\n         1  1.000000E+00  0.000000E+00  0.000000E+00\n         2  0.000000E+00  0.000000E+00  0.000000E+00\n";
        let s = parse_dat(dat, 2).unwrap();
        assert_eq!(s.displacement, vec![[0.0, 3.0, 0.0], [2.0, 0.0, -1.5e-3]]);
        assert_eq!(s.force[0], [1.0, 0.0, 0.0]);
        assert!(parse_dat(dat, 3).unwrap_err().contains("2 of 3"));
        assert!(parse_dat("", 2).is_err());
    }
}
