//! facesim's volumetric model against an independent engine, CalculiX (docs/crosscheck.md):
//! linear tetrahedra on a sheared two-material cube agree to 1e-6 relative (ν = 0.45/0.3 and
//! ν = 0.49); a tets.vtu read back and handed to CalculiX (cells, materials, the displacements
//! of its fixed and moved nodes) reproduces the file's free-node displacements (the CASE.md
//! property). These tests fail, not skip, when `ccx` is missing: run scripts/test-setup.sh.

use facesim::tet::vtu::{self, Cells, TetsVtu};
use facesim::tet::{Elastic, TetMesh};
use facesim_lab::calculix::{self, Dof, Material, Problem, Step};

#[path = "../../facesim/tests/common/tet_grid.rs"]
mod tet_grid;

const FAT: Elastic = Elastic {
    youngs_kpa: 3.0,
    poisson: 0.45,
};
const MUSCLE: Elastic = Elastic {
    youngs_kpa: 15.0,
    poisson: 0.3,
};

/// max |a − b| / max |b| over the nodes where `keep` holds.
fn relative(a: &[[f64; 3]], b: &[[f64; 3]], keep: &dyn Fn(usize) -> bool) -> f64 {
    let (mut diff, mut size) = (0.0_f64, 0.0_f64);
    for i in (0..a.len()).filter(|&i| keep(i)) {
        for c in 0..3 {
            diff = diff.max((a[i][c] - b[i][c]).abs());
            size = size.max(b[i][c].abs());
        }
    }
    diff / size
}

/// The cube's bottom (z = 0) held still and its top moved by a displacement that is not a
/// linear field (a translation, a shear and a twist-like bilinear term); the sides are free.
fn bottom_fixed_top_moved(m: &TetMesh) -> Vec<Option<[f64; 3]>> {
    let top = m.nodes.iter().map(|p| p[2]).fold(0.0, f64::max);
    m.nodes
        .iter()
        .map(|p| {
            if p[2].abs() < 1e-9 {
                Some([0.0; 3])
            } else if (p[2] - top).abs() < 1e-9 {
                Some([
                    0.6 + 0.02 * p[1],
                    -0.3 + 0.03 * p[0],
                    -0.8 + 0.002 * p[0] * p[1],
                ])
            } else {
                None
            }
        })
        .collect()
}

fn problem<'a>(
    m: &'a TetMesh,
    material: &'a [Material],
    held: &'a [Dof],
    step: Step,
) -> Problem<'a> {
    Problem {
        nodes: &m.nodes,
        cells: Cells::Linear(&m.tets),
        material,
        held,
        loads: &[],
        step,
    }
}

#[test]
fn linear_tetrahedra_agree_with_calculix() {
    for (soft, stiff) in [
        (FAT, MUSCLE),
        (
            Elastic {
                poisson: 0.49,
                ..FAT
            },
            Elastic {
                poisson: 0.49,
                ..MUSCLE
            },
        ),
    ] {
        // 8³ cubes of 2.5 mm: 729 nodes, 3072 tetrahedra, fat and muscle in a checkerboard.
        let m = tet_grid::cube(8, 2.5, soft, stiff);
        let prescribed = bottom_fixed_top_moved(&m);
        let ours = m.solve_linear(&prescribed).unwrap();
        let held = calculix::held_nodes(&prescribed);
        let material = calculix::materials(&m);
        let p = problem(&m, &material, &held, Step::LINEAR);
        let printed = calculix::solve(&p).unwrap().displacement;
        let precise = calculix::solve_precise(&p).unwrap().displacement;
        let all = |_| true;
        let (e_printed, e_precise) = (
            relative(&printed, &ours, &all),
            relative(&precise, &ours, &all),
        );
        println!(
            "ν = {}/{}: CalculiX C3D4 vs facesim, max |Δu| / max |u|: {e_printed:.2e} as printed (7 digits), {e_precise:.2e} refined",
            soft.poisson, stiff.poisson
        );
        assert!(e_printed < 1e-6, "{e_printed:e}");
        assert!(e_precise < 1e-9, "{e_precise:e}");

        // The comparison can fail: the two tissues swapped is a different answer.
        let swapped: Vec<Material> = m
            .material
            .iter()
            .map(|e| Material::linear(if *e == soft { stiff } else { soft }))
            .collect();
        let other = calculix::solve(&problem(&m, &swapped, &held, Step::LINEAR))
            .unwrap()
            .displacement;
        let e_swapped = relative(&other, &ours, &all);
        assert!(e_swapped > 1e-2, "{e_swapped:e}");
    }
}

#[test]
fn tets_vtu_free_nodes_are_reproduced_by_calculix() {
    let m = tet_grid::cube(8, 2.5, FAT, MUSCLE);
    let top = m.nodes.iter().map(|p| p[2]).fold(0.0, f64::max);
    // Bottom fixed to the skull (1); top moved with a bone segment (2): 4° about z through
    // (10, 10, top) and a 2 mm advancement; the rest free (0).
    let (s, c) = 4.0_f64.to_radians().sin_cos();
    let constraint: Vec<u8> = m
        .nodes
        .iter()
        .map(|p| {
            if p[2].abs() < 1e-9 {
                vtu::FIXED
            } else if (p[2] - top).abs() < 1e-9 {
                vtu::MOVED
            } else {
                vtu::FREE
            }
        })
        .collect();
    let prescribed: Vec<Option<[f64; 3]>> = m
        .nodes
        .iter()
        .zip(&constraint)
        .map(|(p, &k)| match k {
            vtu::FIXED => Some([0.0; 3]),
            vtu::MOVED => {
                let (x, y) = (p[0] - 10.0, p[1] - 10.0);
                Some([c * x - s * y - x, s * x + c * y - y + 2.0, 0.0])
            }
            _ => None,
        })
        .collect();
    let displacement = m.solve_linear(&prescribed).unwrap();
    let tissue: Vec<u8> = m
        .material
        .iter()
        .map(|e| if *e == FAT { 3 } else { 4 })
        .collect();
    let youngs: Vec<f64> = m.material.iter().map(|e| e.youngs_kpa).collect();
    let poisson: Vec<f64> = m.material.iter().map(|e| e.poisson).collect();
    let written = TetsVtu {
        nodes: &m.nodes,
        cells: Cells::Linear(&m.tets),
        displacement: &displacement,
        constraint: &constraint,
        youngs_kpa: &youngs,
        poisson: &poisson,
        tissue: &tissue,
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tets.vtu");
    vtu::write(&path, &written).unwrap();

    // Everything below uses only the file.
    let f = vtu::read(&path).unwrap();
    assert_eq!(f.nodes, m.nodes);
    assert_eq!(f.displacement, displacement, "bit-exact round trip");
    let material: Vec<Material> = f
        .youngs_kpa
        .iter()
        .zip(&f.poisson)
        .map(|(&youngs_kpa, &poisson)| Material::Linear {
            youngs_kpa,
            poisson,
        })
        .collect();
    let d = &f.displacement;
    let held: Vec<Dof> = (0..f.nodes.len())
        .filter(|&n| f.constraint[n] == vtu::FIXED || f.constraint[n] == vtu::MOVED)
        .flat_map(|n| {
            (0..3).map(move |axis| Dof {
                node: n as u32,
                axis,
                value: d[n][axis],
            })
        })
        .collect();
    let u = calculix::solve_precise(&Problem {
        nodes: &f.nodes,
        cells: f.cells.view(),
        material: &material,
        held: &held,
        loads: &[],
        step: Step::LINEAR,
    })
    .unwrap()
    .displacement;
    let free = |n: usize| f.constraint[n] == vtu::FREE;
    let e = relative(&u, &f.displacement, &free);
    let interior = (0..f.nodes.len()).filter(|&n| free(n)).count();
    println!("tets.vtu: {interior} free nodes re-solved by CalculiX, max |Δu| / max |u| = {e:.2e}");
    assert!(interior > 400);
    assert!(e < 1e-6, "{e:e}");
}

#[test]
fn a_malformed_tets_vtu_is_a_one_line_error_naming_the_file() {
    let m = tet_grid::cube(2, 1.0, FAT, MUSCLE);
    let n = m.nodes.len();
    let c = m.tets.len();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tets.vtu");
    vtu::write(
        &path,
        &TetsVtu {
            nodes: &m.nodes,
            cells: Cells::Linear(&m.tets),
            displacement: &vec![[0.0; 3]; n],
            constraint: &vec![0; n],
            youngs_kpa: &vec![3.0; c],
            poisson: &vec![0.45; c],
            tissue: &vec![3; c],
        },
    )
    .unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    // Cut short mid-way (an interrupted copy), and a cell naming a node that is not there.
    for broken in [
        text[..text.len() / 2].to_string(),
        text.replacen(
            "<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n0 ",
            "<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n99999 ",
            1,
        ),
    ] {
        assert_ne!(broken, text);
        std::fs::write(&path, &broken).unwrap();
        let e = vtu::read(&path).unwrap_err().to_string();
        assert!(
            e.starts_with(&path.display().to_string()) && !e.contains('\n'),
            "{e}"
        );
        println!("{e}");
    }
}
