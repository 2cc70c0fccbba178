//! facesim's volumetric model against an independent engine, CalculiX (docs/design/crosscheck.md):
//! linear tetrahedra on a sheared two-material cube agree to 1e-6 relative (ν = 0.45/0.3 and
//! ν = 0.49); a tets.vtu read back and handed to CalculiX (cells, materials, the displacements
//! of its fixed and moved nodes) reproduces the file's free-node displacements (the docs/reference/case.md
//! property); CalculiX's own NLGEOM neo-Hooke matches the closed-form uniaxial stretch and its
//! C3D10 reproduces a quadratic solution, so both are references; facesim's quadratic
//! tetrahedra agree with C3D10 (held move, nodal forces), face pressures with `*DLOAD` on C3D4
//! and C3D10, and the neo-Hookean option with CalculiX's NLGEOM NEO HOOKE on a jaw-turn problem
//! far below the h vs h/2 discretisation difference. These tests fail, not skip, when `ccx` is
//! missing: run scripts/test-setup.sh.

// Numerics index arrays by axis and node, as in the crates.
#![allow(clippy::needless_range_loop)]

use facesim::tet::vtu::{self, Cells, TetsVtu};
use facesim::tet::{TetMesh, TissueElastic};
use facesim_lab::calculix::{self, Dof, Material, Problem, Step};

#[path = "../../facesim/tests/common/tet_grid.rs"]
mod tet_grid;

const FAT: TissueElastic = TissueElastic {
    youngs_kpa: 3.0,
    poisson: 0.45,
};
const MUSCLE: TissueElastic = TissueElastic {
    youngs_kpa: 15.0,
    poisson: 0.3,
};

/// facesim-calculix's measure of two engines' difference.
fn relative(a: &[[f64; 3]], b: &[[f64; 3]], keep: &dyn Fn(usize) -> bool) -> f64 {
    calculix::relative_difference(a, b, keep)
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
        pressure: &[],
        step,
    }
}

#[test]
fn linear_tetrahedra_agree_with_calculix() {
    for (soft, stiff) in [
        (FAT, MUSCLE),
        (
            TissueElastic {
                poisson: 0.49,
                ..FAT
            },
            TissueElastic {
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
    // Kept under target/tmp so the file can be opened in ParaView or meshio after a run.
    let dir = tempfile::Builder::new()
        .prefix("facesim-tets-vtu")
        .tempdir_in(env!("CARGO_TARGET_TMPDIR"))
        .unwrap()
        .keep();
    let path = dir.join("tets.vtu");
    vtu::write(&path, &written).unwrap();

    // Everything below uses only the file.
    let f = vtu::read(&path).unwrap();
    assert_eq!(f.nodes, m.nodes);
    assert_eq!(f.displacement, displacement, "bit-exact round trip");
    let material = calculix::linear_materials(&f.youngs_kpa, &f.poisson);
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
        pressure: &[],
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

/// The grid nodes of [0, side]³ in n steps (not sheared, so the faces are coordinate planes)
/// and its Kuhn tetrahedra.
fn box_grid(n: usize, side: f64) -> (Vec<[f64; 3]>, Vec<[u32; 4]>) {
    let id = |i: usize, j: usize, k: usize| ((k * (n + 1) + j) * (n + 1) + i) as u32;
    let h = side / n as f64;
    let mut nodes = Vec::new();
    for k in 0..=n {
        for j in 0..=n {
            for i in 0..=n {
                nodes.push([i as f64 * h, j as f64 * h, k as f64 * h]);
            }
        }
    }
    let mut tets = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                tets.extend(tet_grid::kuhn_cell([i, j, k], &id, &nodes));
            }
        }
    }
    (nodes, tets)
}

/// Cauchy stresses (σ_xx, σ_yy = σ_zz) of U = C10 (Ī1 − 3) + (J − 1)² / D1 under
/// F = diag(λ, t, t): σ = (2 C10 / J) dev(B̄) + (2 / D1)(J − 1) I with B̄ = J^(−2/3) F Fᵀ.
fn neo_hooke_stress(c10: f64, d1: f64, l: f64, t: f64) -> (f64, f64) {
    let j = l * t * t;
    let a = 2.0 * c10 / j * j.powf(-2.0 / 3.0);
    let p = 2.0 / d1 * (j - 1.0);
    (
        a * 2.0 / 3.0 * (l * l - t * t) + p,
        a / 3.0 * (t * t - l * l) + p,
    )
}

#[test]
fn calculix_nlgeom_neo_hooke_matches_the_closed_form_uniaxial_stretch() {
    // A 10 mm cube stretched by 30 % along x on three symmetry planes, the other faces free:
    // the deformation is homogeneous, F = diag(λ, t, t), with t from σ_yy(t) = 0.
    let (side, stretch) = (10.0, 1.3);
    let (nodes, tets) = box_grid(2, side);
    let m = Material::neo_hooke(MUSCLE);
    let Material::NeoHooke { c10, d1 } = m else {
        unreachable!()
    };
    let on = |v: f64, at: f64| (v - at).abs() < 1e-9;
    let mut held = Vec::new();
    for (n, p) in nodes.iter().enumerate() {
        for axis in 0..3 {
            if on(p[axis], 0.0) {
                held.push(Dof {
                    node: n as u32,
                    axis,
                    value: 0.0,
                });
            }
        }
        if on(p[0], side) {
            held.push(Dof {
                node: n as u32,
                axis: 0,
                value: (stretch - 1.0) * side,
            });
        }
    }
    let sol = calculix::solve(&Problem {
        nodes: &nodes,
        cells: Cells::Linear(&tets),
        material: &vec![m; tets.len()],
        held: &held,
        loads: &[],
        pressure: &[],
        step: Step {
            nlgeom: true,
            increments: 10,
        },
    })
    .unwrap();

    // The closed form: bisection on σ_yy(t) = 0 (σ_yy rises with t through the root).
    let (mut lo, mut hi) = (0.5, 1.0);
    assert!(neo_hooke_stress(c10, d1, stretch, lo).1 < 0.0);
    assert!(neo_hooke_stress(c10, d1, stretch, hi).1 > 0.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if neo_hooke_stress(c10, d1, stretch, mid).1 < 0.0 {
            lo = mid
        } else {
            hi = mid
        }
    }
    let t = 0.5 * (lo + hi);
    let (sxx, _) = neo_hooke_stress(c10, d1, stretch, t);
    // Every node on the homogeneous field, and the end force σ_xx times the deformed area.
    let mut worst: f64 = 0.0;
    for (p, u) in nodes.iter().zip(&sol.displacement) {
        let exact = [(stretch - 1.0) * p[0], (t - 1.0) * p[1], (t - 1.0) * p[2]];
        for c in 0..3 {
            worst = worst.max((u[c] - exact[c]).abs() / ((stretch - 1.0) * side));
        }
    }
    let force: f64 = nodes
        .iter()
        .zip(&sol.force)
        .filter(|(p, _)| on(p[0], side))
        .map(|(_, f)| f[0])
        .sum();
    let exact_force = sxx * (t * side).powi(2);
    let e_force = (force - exact_force).abs() / exact_force;
    // Small strain would give t = 1 − ν (λ − 1) = 0.91; the finite-strain answer differs.
    println!(
        "neo-Hooke uniaxial λ = {stretch}: t = {t:.6} (closed form), nodal error {worst:.1e} of the stretch, end force {force:.6e} vs {exact_force:.6e} ({e_force:.1e})"
    );
    assert!((t - 0.91).abs() > 5e-3, "t = {t}");
    assert!(worst < 1e-6, "{worst:e}");
    assert!(e_force < 1e-5, "{e_force:e}");
}

#[test]
fn calculix_c3d10_reproduces_a_quadratic_solution_exactly() {
    // u = a (x² − y², −2xy, 0) + a linear field is harmonic and divergence-free, so it solves
    // homogeneous isotropic elasticity without body force (μ Δu + (λ + μ) ∇ div u = 0):
    // quadratic tetrahedra with exact boundary values reproduce it at every node.
    let mut m = tet_grid::cube(4, 1.5, MUSCLE, MUSCLE);
    let exact = |p: [f64; 3]| {
        let a = 0.01;
        [
            a * (p[0] * p[0] - p[1] * p[1]) + 0.02 * p[2],
            -2.0 * a * p[0] * p[1] - 0.01 * p[0],
            0.03 * p[1],
        ]
    };
    // Boundary nodes: on a face of the (sheared) cube, i.e. not strictly inside it.
    let span = 6.0;
    let boundary = |p: [f64; 3]| {
        let z = p[2];
        let y = p[1] - 0.05 * z;
        let x = p[0] - 0.1 * y;
        [x, y, z]
            .iter()
            .any(|v| v.abs() < 1e-9 || (v - span).abs() < 1e-9)
    };
    // Interior nodes jittered by up to 0.2 h: on the uniform grid even linear tetrahedra are
    // nodally exact for this field (superconvergence), which would leave the control blind.
    for (n, p) in m.nodes.iter_mut().enumerate() {
        if !boundary(*p) {
            for c in 0..3 {
                p[c] += 0.3 * (1.7 * n as f64 + 2.3 * c as f64).sin();
            }
        }
    }
    assert!(
        m.tets
            .iter()
            .all(|t| facesim::tet::gradients(t.map(|v| m.nodes[v as usize])).is_some())
    );
    // Mid-edge nodes, one per edge, in VTK / C3D10 order.
    let mut nodes = m.nodes.clone();
    let mut mid = std::collections::HashMap::new();
    let quad: Vec<[u32; 10]> = m
        .tets
        .iter()
        .map(|t| {
            let mut q = [0; 10];
            q[..4].copy_from_slice(t);
            for (k, (a, b)) in [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)]
                .into_iter()
                .enumerate()
            {
                let key = (t[a].min(t[b]), t[a].max(t[b]));
                q[4 + k] = *mid.entry(key).or_insert_with(|| {
                    let (p, r) = (nodes[t[a] as usize], nodes[t[b] as usize]);
                    nodes.push(std::array::from_fn(|c| 0.5 * (p[c] + r[c])));
                    (nodes.len() - 1) as u32
                });
            }
            q
        })
        .collect();
    let held_of = |nodes: &[[f64; 3]]| -> Vec<Dof> {
        (0..nodes.len())
            .filter(|&n| boundary(nodes[n]))
            .flat_map(|n| {
                let u = exact(nodes[n]);
                (0..3).map(move |axis| Dof {
                    node: n as u32,
                    axis,
                    value: u[axis],
                })
            })
            .collect()
    };
    let solve = |nodes: &[[f64; 3]], cells: Cells| {
        let held = held_of(nodes);
        assert!(held.len() < 3 * nodes.len(), "interior nodes exist");
        let u = calculix::solve_precise(&Problem {
            nodes,
            cells,
            material: &vec![Material::linear(MUSCLE); cells.len()],
            held: &held,
            loads: &[],
            pressure: &[],
            step: Step::LINEAR,
        })
        .unwrap()
        .displacement;
        let e: Vec<[f64; 3]> = nodes.iter().map(|p| exact(*p)).collect();
        relative(&u, &e, &|_| true)
    };
    let quadratic = solve(&nodes, Cells::Quadratic(&quad));
    let linear = solve(&m.nodes, Cells::Linear(&m.tets));
    println!("quadratic field: C3D10 error {quadratic:.1e}, C3D4 {linear:.1e} (relative)");
    assert!(quadratic < 1e-9, "{quadratic:e}");
    assert!(linear > 1e-4, "the linear element cannot: {linear:e}");
}

// ---------------------------------------------------------------------------------------------
// The nonlinear (neo-Hookean) option against CalculiX's NLGEOM NEO HOOKE.

type V3 = [f64; 3];

/// The rotation by `deg` about `axis` (Rodrigues: I + sin θ [k]× + (1 − cos θ) [k]×²).
fn rotation(axis: V3, deg: f64) -> [[f64; 3]; 3] {
    let l = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let k = axis.map(|c| c / l);
    let (s, c) = deg.to_radians().sin_cos();
    let kx = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]];
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let id = if i == j { 1.0 } else { 0.0 };
            let kk: f64 = (0..3).map(|m| kx[i][m] * kx[m][j]).sum();
            id + s * kx[i][j] + (1.0 - c) * kk
        })
    })
}

/// A block of `cells` Kuhn cells of side h: muscle below z = 5 mm, fat above (the interface
/// is a grid plane of every mesh with 5 / h whole). Returns the mesh and the grid indices.
fn tissue_block(cells: [usize; 3], h: f64) -> (TetMesh, Vec<[usize; 3]>) {
    let id = |i: usize, j: usize, k: usize| ((k * (cells[1] + 1) + j) * (cells[0] + 1) + i) as u32;
    let mut nodes = Vec::new();
    let mut ijk = Vec::new();
    for k in 0..=cells[2] {
        for j in 0..=cells[1] {
            for i in 0..=cells[0] {
                nodes.push([i as f64 * h, j as f64 * h, k as f64 * h]);
                ijk.push([i, j, k]);
            }
        }
    }
    let (mut tets, mut material) = (Vec::new(), Vec::new());
    for k in 0..cells[2] {
        for j in 0..cells[1] {
            for i in 0..cells[0] {
                for t in tet_grid::kuhn_cell([i, j, k], &id, &nodes) {
                    tets.push(t);
                    material.push(if ((k as f64 + 0.5) * h) < 5.0 {
                        MUSCLE
                    } else {
                        FAT
                    });
                }
            }
        }
    }
    (
        TetMesh {
            nodes,
            tets,
            material,
        },
        ijk,
    )
}

/// Tissue between a fixed skull (the face x = 0) and a moved jaw (the bottom nodes with
/// x ≥ 10 mm): the jaw turned by 18° s about an oblique axis through (15, 10, 0) and
/// translated by s (−1, 0.5, 1.5) mm; the top and the other sides free. Bone nodes get their
/// total displacement (R − I)(x − c) + t, as facesim's pipeline gives them.
fn jaw_holds(m: &TetMesh, ijk: &[[usize; 3]], cells: [usize; 3], s: f64) -> Vec<Option<V3>> {
    let r = rotation([0.4, 1.0, 0.3], 18.0 * s);
    let (c, t) = ([15.0, 10.0, 0.0], [-s, 0.5 * s, 1.5 * s]);
    m.nodes
        .iter()
        .zip(ijk)
        .map(|(p, g)| {
            if g[0] == 0 {
                Some([0.0; 3])
            } else if g[2] == 0 && 2 * g[0] >= cells[0] {
                let d: V3 = std::array::from_fn(|k| p[k] - c[k]);
                Some(std::array::from_fn(|i| {
                    (0..3).map(|j| r[i][j] * d[j]).sum::<f64>() - d[i] + t[i]
                }))
            } else {
                None
            }
        })
        .collect()
}

/// max |a − b| / max |b| over the coarse mesh's nodes, `b` and `a` on meshes whose grid indices
/// are `ijk` and twice those (every coarse node is a fine node).
fn coarse_nodes_relative(
    coarse: &[V3],
    ijk: &[[usize; 3]],
    fine: &[V3],
    fine_cells: [usize; 3],
) -> f64 {
    let id = |[i, j, k]: [usize; 3]| {
        ((2 * k * (fine_cells[1] + 1) + 2 * j) * (fine_cells[0] + 1)) + 2 * i
    };
    let sampled: Vec<V3> = ijk.iter().map(|g| fine[id(*g)]).collect();
    relative(&sampled, coarse, &|_| true)
}

#[test]
fn neo_hookean_tetrahedra_agree_with_calculix_nlgeom_far_below_the_discretisation_difference() {
    use facesim::tet::nonlinear::{self, Newton};
    use facesim::tet::{Hold, Loads};
    let solve_ours = |cells: [usize; 3], h: f64, s: f64| {
        let (m, ijk) = tissue_block(cells, h);
        let prescribed = jaw_holds(&m, &ijk, cells, s);
        let holds: Vec<Hold> = prescribed
            .iter()
            .map(|p| p.map_or(Hold::Free, Hold::Fixed))
            .collect();
        let opts = Newton {
            energy: nonlinear::Energy::CalculixNeoHooke,
            ..Newton::default()
        };
        let sol = nonlinear::solve(&m, &holds, &Loads::none(), &opts).unwrap();
        (m, ijk, prescribed, sol.displacements)
    };
    let neo = |m: &TetMesh| -> Vec<Material> {
        m.material.iter().map(|e| Material::neo_hooke(*e)).collect()
    };
    // CalculiX, NLGEOM: the bone displacements ramped linearly over the step's increments (the
    // path differs from a rigid turn, the end state does not: one hyperelastic equilibrium).
    let calculix_nlgeom = |m: &TetMesh, prescribed: &[Option<V3>], increments: u32| {
        let held = calculix::held_nodes(prescribed);
        let material = neo(m);
        let step = Step {
            nlgeom: true,
            increments,
        };
        calculix::solve(&problem(m, &material, &held, step))
            .unwrap()
            .displacement
    };
    // A 20 × 20 × 10 mm block at h = 2.5 mm (405 nodes, 1536 tetrahedra) and h / 2 (2601
    // nodes, 12288 tetrahedra); every coarse node is a fine node.
    let (coarse, fine) = ([8, 8, 4], [16, 16, 8]);
    let (m, ijk, prescribed, u) = solve_ours(coarse, 2.5, 1.0);
    let (mf, _, prescribed_f, uf) = solve_ours(fine, 1.25, 1.0);
    let theirs = calculix_nlgeom(&m, &prescribed, 10);
    let theirs_f = calculix_nlgeom(&mf, &prescribed_f, 4);
    let all = |_| true;
    let (engine, engine_f) = (relative(&theirs, &u, &all), relative(&theirs_f, &uf, &all));
    let disc = coarse_nodes_relative(&u, &ijk, &uf, fine);
    let disc_theirs = coarse_nodes_relative(&theirs, &ijk, &theirs_f, fine);

    // CalculiX's internal forces at facesim's displacement (every component held there): on
    // the free nodes, facesim's residual in CalculiX's discrete equations. Each (tiny) value is
    // printed to 7 significant digits, so this figure is not limited by the printing.
    let every: Vec<Dof> = (0..3 * m.nodes.len())
        .map(|i| Dof {
            node: (i / 3) as u32,
            axis: i % 3,
            value: u[i / 3][i % 3],
        })
        .collect();
    let one = Step {
        nlgeom: true,
        increments: 1,
    };
    let force = calculix::solve(&problem(&m, &neo(&m), &every, one))
        .unwrap()
        .force;
    let (mut on_free, mut on_held) = (0.0_f64, 0.0_f64);
    for (p, f) in prescribed.iter().zip(&force) {
        let norm = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        match p {
            Some(_) => on_held = on_held.max(norm),
            None => on_free = on_free.max(norm),
        }
    }
    let residual = on_free / on_held;

    // A plausible slip in the material, K = λ instead of λ + 2μ/3 in D1, is seen at once.
    let slip: Vec<Material> = m
        .material
        .iter()
        .map(|e| Material::NeoHooke {
            c10: e.lame().1 / 2.0,
            d1: 2.0 / e.lame().0,
        })
        .collect();
    let held = calculix::held_nodes(&prescribed);
    let slipped = calculix::solve(&problem(
        &m,
        &slip,
        &held,
        Step {
            nlgeom: true,
            increments: 10,
        },
    ))
    .unwrap()
    .displacement;
    let e_slip = relative(&slipped, &u, &all);

    // The small-strain model on the same mesh and move, at the full move and at half of it:
    // its error is second order in the move, so relative to |u| it halves with the move.
    let linear = m.solve_linear(&prescribed).unwrap();
    let (lin_ours, lin_theirs) = (
        relative(&linear, &u, &all),
        relative(&linear, &theirs, &all),
    );
    let (_, _, half, u_half) = solve_ours(coarse, 2.5, 0.5);
    let lin_half = relative(&m.solve_linear(&half).unwrap(), &u_half, &all);

    let max_u = u.iter().flatten().fold(0.0_f64, |a, b| a.max(b.abs()));
    println!(
        "neo-Hooke, jaw turned 18° + 1.9 mm (max |u| {max_u:.2} mm): CalculiX NLGEOM vs facesim, max |Δu| / max |u| = {engine:.2e} (h = 2.5 mm), {engine_f:.2e} (h = 1.25 mm); CalculiX's forces at facesim's answer, max free / max held = {residual:.1e}"
    );
    println!(
        "  discretisation difference, h vs h/2 at the coarse nodes: {disc:.3e} (facesim), {disc_theirs:.3e} (CalculiX); engine / discretisation = {:.1e}; CalculiX with D1 = 2/λ (a slip) differs by {e_slip:.1e}",
        engine / disc
    );
    println!(
        "  small-strain linear model: {lin_ours:.2e} from facesim's neo-Hooke, {lin_theirs:.2e} from CalculiX's; at half the move {lin_half:.2e} (ratio {:.2})",
        lin_ours / lin_half
    );
    // The same discrete problem: agreement to the 7 printed digits, facesim's answer in
    // equilibrium in CalculiX's equations to round-off.
    assert!(engine < 1e-6 && engine_f < 1e-6, "{engine:e} {engine_f:e}");
    assert!(residual < 1e-10, "{residual:e}");
    // Far below the discretisation difference, which both engines measure alike.
    assert!(disc > 1e-3, "{disc:e}");
    assert!(engine < 1e-3 * disc, "{engine:e} vs {disc:e}");
    assert!(
        (disc - disc_theirs).abs() < 1e-2 * disc,
        "{disc:e} {disc_theirs:e}"
    );
    assert!(e_slip > 1e3 * engine, "{e_slip:e}");
    // The comparison tells the linear model apart.
    assert!(lin_ours > 1e-2 && lin_theirs > 1e4 * engine, "{lin_ours:e}");
    assert!(
        (1.6..2.4).contains(&(lin_ours / lin_half)),
        "{lin_ours:e} {lin_half:e}"
    );
}

// ---------------------------------------------------------------------------------------------
// Quadratic (10-node) tetrahedra against CalculiX's C3D10.

/// The side of the cube of the quadratic and pressure tests (6 cells of 2 mm).
const SPAN: f64 = 12.0;

/// A point's coordinates in the sheared cube's own frame (the shear of `tet_grid::cube`
/// undone), where its faces are the planes 0 and SPAN.
fn unsheared(p: V3) -> V3 {
    let y = p[1] - 0.05 * p[2];
    [p[0] - 0.1 * y, y, p[2]]
}

/// The mesh of the quadratic test, its 10-node version and the held displacements (None: free).
fn jittered_quadratic_cube(
    rule: facesim::tet::quadratic::Rule,
) -> (TetMesh, facesim::tet::quadratic::Tet10Mesh, Vec<Option<V3>>) {
    use facesim::tet::quadratic::Tet10Mesh;
    // A sheared 6³ cube of 2 mm cells, fat and muscle in a checkerboard, interior corners
    // jittered by up to 0.2 h (no element keeps the grid's symmetry), mid-edge nodes added.
    let (n, h) = (6, 2.0);
    let span = n as f64 * h;
    let mut m = tet_grid::cube(n, h, FAT, MUSCLE);
    let on_face = |p: V3| {
        unsheared(p)
            .iter()
            .any(|v| v.abs() < 1e-9 || (v - SPAN).abs() < 1e-9)
    };
    for (k, p) in m.nodes.iter_mut().enumerate() {
        if !on_face(*p) {
            for c in 0..3 {
                p[c] += 0.2 * h * (1.7 * k as f64 + 2.3 * c as f64).sin();
            }
        }
    }
    let q = Tet10Mesh::from_linear(&m, rule);
    // Bottom held, top moved obliquely (translation, shear and a bilinear term at the corners);
    // a held mid-edge node takes the mean of its edge's corners (the quadratic field along a
    // held edge is then the linear interpolation of the corner values).
    let corner_holds = bottom_fixed_top_moved(&m);
    let mut prescribed: Vec<Option<V3>> = corner_holds.clone();
    for [a, b] in &q.edges {
        let (pa, pb) = (corner_holds[*a as usize], corner_holds[*b as usize]);
        let both_bottom =
            m.nodes[*a as usize][2].abs() < 1e-9 && m.nodes[*b as usize][2].abs() < 1e-9;
        let both_top = (m.nodes[*a as usize][2] - span).abs() < 1e-9
            && (m.nodes[*b as usize][2] - span).abs() < 1e-9;
        prescribed.push(match (pa, pb) {
            (Some(ua), Some(ub)) if both_bottom || both_top => {
                Some(std::array::from_fn(|c| 0.5 * (ua[c] + ub[c])))
            }
            _ => None,
        });
    }
    assert_eq!(prescribed.len(), q.nodes.len());
    assert!((span - SPAN).abs() < 1e-12);
    (m, q, prescribed)
}

#[test]
fn quadratic_tetrahedra_agree_with_calculix_c3d10() {
    use facesim::tet::quadratic::{Rule, Tet10Mesh};
    use facesim::tet::{Hold, Loads};
    let (m, q, prescribed) = jittered_quadratic_cube(Rule::Full);
    // Nodal forces (mN) on the free nodes of the side x = span, corners and mid-edge nodes alike.
    let loaded: Vec<(usize, V3)> = (0..q.nodes.len())
        .filter(|&k| prescribed[k].is_none() && (unsheared(q.nodes[k])[0] - SPAN).abs() < 1e-9)
        .map(|k| (k, [0.3, -0.2 + 0.01 * k as f64 % 0.1, 0.25]))
        .collect();
    assert!(
        loaded.iter().any(|(k, _)| *k < q.corners) && loaded.iter().any(|(k, _)| *k >= q.corners)
    );
    let holds: Vec<Hold> = prescribed
        .iter()
        .map(|p| p.map_or(Hold::Free, Hold::Fixed))
        .collect();
    let ours = q
        .solve(
            &holds,
            &Loads {
                nodal: loaded.clone(),
                pressure: vec![],
            },
        )
        .unwrap();

    let held = calculix::held_nodes(&prescribed);
    let loads: Vec<Dof> = loaded
        .iter()
        .flat_map(|(k, f)| {
            (0..3).map(move |axis| Dof {
                node: *k as u32,
                axis,
                value: f[axis],
            })
        })
        .collect();
    let material = calculix::materials(&m);
    let p = Problem {
        nodes: &q.nodes,
        cells: Cells::Quadratic(&q.tets),
        material: &material,
        held: &held,
        loads: &loads,
        pressure: &[],
        step: Step::LINEAR,
    };
    let printed = calculix::solve(&p).unwrap().displacement;
    let precise = calculix::solve_precise(&p).unwrap().displacement;
    let all = |_| true;
    let (e_printed, e_precise) = (
        relative(&printed, &ours, &all),
        relative(&precise, &ours, &all),
    );
    // The held move alone: refinement is then limited by round-off only. With loads, the
    // residual f − K u₁ at a loaded node is the difference of the load and CalculiX's nodal
    // force printed to 7 digits (≈ 5e-7 of the load), which bounds the refined agreement.
    let ours_holds = q.solve(&holds, &Loads::none()).unwrap();
    let unloaded = calculix::solve_precise(&Problem { loads: &[], ..p })
        .unwrap()
        .displacement;
    let e_holds = relative(&unloaded, &ours_holds, &all);
    // Controls: the loads left out, and facesim's mean-dilatation rule, are other answers.
    let e_unloaded = relative(&unloaded, &ours, &all);
    let mean_dilatation = Tet10Mesh::from_linear(&m, Rule::MeanDilatation)
        .solve(
            &holds,
            &Loads {
                nodal: loaded.clone(),
                pressure: vec![],
            },
        )
        .unwrap();
    let e_md = relative(&precise, &mean_dilatation, &all);
    println!(
        "C3D10 vs facesim Tet10Mesh (Rule::Full), {} nodes, {} tetrahedra, held move + {} loaded nodes: max |Δu| / max |u| = {e_printed:.2e} as printed, {e_precise:.2e} refined; held move alone {e_holds:.2e} refined; controls: without the loads {e_unloaded:.1e}, facesim's mean-dilatation rule {e_md:.1e}",
        q.nodes.len(),
        q.tets.len(),
        loaded.len()
    );
    assert!(e_printed < 1e-6, "{e_printed:e}");
    assert!(e_precise < 1e-7, "{e_precise:e}");
    assert!(e_holds < 1e-9, "{e_holds:e}");
    assert!(e_unloaded > 1e-3 && e_md > 1e-4, "{e_unloaded:e} {e_md:e}");
}

#[test]
fn face_pressure_agrees_with_calculix_dload_on_linear_and_quadratic_tetrahedra() {
    use facesim::tet::quadratic::Rule;
    use facesim::tet::{Hold, Loads};
    use facesim_lab::calculix::Pressure;
    // The quadratic test's cube and held move, and a pressure on the side y = SPAN, pushing in,
    // rising linearly along x (a different value per face).
    let (m, q, prescribed) = jittered_quadratic_cube(Rule::Full);
    let mut faces: Vec<(u32, [u32; 3], f64)> = Vec::new();
    for (cell, t) in m.tets.iter().enumerate() {
        for skip in 0..4 {
            let mut f: Vec<u32> = (0..4).filter(|&k| k != skip).map(|k| t[k]).collect();
            let on_side = f
                .iter()
                .all(|&v| (unsheared(m.nodes[v as usize])[1] - SPAN).abs() < 1e-9);
            if !on_side {
                continue;
            }
            // facesim's faces wind counter-clockwise seen from outside: away from the 4th corner.
            let x = |v: u32| m.nodes[v as usize];
            let (a, b, c, d) = (x(f[0]), x(f[1]), x(f[2]), x(t[skip]));
            let e1: V3 = std::array::from_fn(|k| b[k] - a[k]);
            let e2: V3 = std::array::from_fn(|k| c[k] - a[k]);
            let n = [
                e1[1] * e2[2] - e1[2] * e2[1],
                e1[2] * e2[0] - e1[0] * e2[2],
                e1[0] * e2[1] - e1[1] * e2[0],
            ];
            if (0..3).map(|k| n[k] * (d[k] - a[k])).sum::<f64>() > 0.0 {
                f.swap(1, 2);
            }
            let centre_x = (a[0] + b[0] + c[0]) / 3.0;
            faces.push((cell as u32, [f[0], f[1], f[2]], 0.05 + 0.01 * centre_x));
        }
    }
    assert_eq!(faces.len(), 2 * 6 * 6, "two triangles per cell face");
    let loads = Loads {
        nodal: vec![],
        pressure: faces.iter().map(|(_, f, p)| (*f, *p)).collect(),
    };
    let pressure: Vec<Pressure> = faces
        .iter()
        .map(|&(cell, corners, value)| Pressure {
            cell,
            corners,
            value,
        })
        .collect();
    let all = |_| true;
    for quadratic in [false, true] {
        let (nodes, cells, held_at): (&[V3], Cells, Vec<Option<V3>>) = if quadratic {
            (&q.nodes, Cells::Quadratic(&q.tets), prescribed.clone())
        } else {
            (
                &m.nodes,
                Cells::Linear(&m.tets),
                prescribed[..m.nodes.len()].to_vec(),
            )
        };
        let holds: Vec<Hold> = held_at
            .iter()
            .map(|p| p.map_or(Hold::Free, Hold::Fixed))
            .collect();
        let ours = if quadratic {
            q.solve(&holds, &loads).unwrap()
        } else {
            m.solve(&holds, &loads).unwrap()
        };
        let unloaded = if quadratic {
            q.solve(&holds, &Loads::none()).unwrap()
        } else {
            m.solve(&holds, &Loads::none()).unwrap()
        };
        let held = calculix::held_nodes(&held_at);
        let material = calculix::materials(&m);
        let theirs = calculix::solve(&Problem {
            nodes,
            cells,
            material: &material,
            held: &held,
            loads: &[],
            pressure: &pressure,
            step: Step::LINEAR,
        })
        .unwrap()
        .displacement;
        let e = relative(&theirs, &ours, &all);
        let pressure_share = relative(&unloaded, &ours, &all);
        println!(
            "pressure on {} faces, {}: CalculiX *DLOAD vs facesim Loads::pressure, max |Δu| / max |u| = {e:.2e} as printed (the pressure moves the answer by {pressure_share:.1e})",
            faces.len(),
            if quadratic { "C3D10" } else { "C3D4" }
        );
        assert!(e < 1e-6, "{e:e}");
        assert!(pressure_share > 1e-2, "{pressure_share:e}");
    }
}
