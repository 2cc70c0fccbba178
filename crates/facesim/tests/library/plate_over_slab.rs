//! A flat skin plate over a bone slab: planar parameterisation, struts off, edges rigid,
//! bone lifted uniformly. koch1996 turns the lift into a uniform load on the skin — a clamped plate
//! (w_centre = 0.00126532 q a⁴ / D); equilibrium adds the springs to the system — a clamped plate
//! on an elastic foundation, whose reference is the verified C1 plate solver with a Winkler term
//! (crates/facesim/tests/library/c1_plates.rs checks it against Navier's series).

use facesim::fem::assembly::{FemMesh, System};
use facesim::fem::element::Material;
use facesim::volume::Volume;

const A: f64 = 40.0; // plate side (mm)
const T: f64 = 10.0; // soft tissue thickness (mm)
const LIFT: f64 = 0.05; // bone lift (mm): small, the linear regime

/// CT: bone for z < 0, soft tissue 0 < z < T over |x|, |y| < 40, air elsewhere; 1 mm voxels with
/// the boundaries on voxel faces (no partial volume).
fn write_case(dir: &std::path::Path, model: &str, k_c_key: &str, k_c: f64) -> usize {
    let n = [121usize, 121, 41];
    let origin = [-60.0, -60.0, -20.5];
    let mut v = Volume {
        dims: n,
        spacing: [1.0; 3],
        origin,
        direction: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        data: vec![-1000.0; n[0] * n[1] * n[2]],
    };
    for a in 0..v.data.len() {
        let p = v.to_world(v.ijk(a).map(|x| x as f64));
        if p[0].abs() < 40.0 && p[1].abs() < 40.0 && p[2] > -15.0 {
            v.data[a] = if p[2] < 0.0 {
                600.0
            } else if p[2] < T {
                45.0
            } else {
                -1000.0
            };
        }
    }
    facesim::volume::nifti_io::write(&v, &dir.join("ct.nii.gz")).unwrap();
    // The skin: a grid at z = T over the plate, triangles facing +z.
    let m = 20;
    let h = A / m as f64;
    let mut verts = Vec::new();
    for j in 0..=m {
        for i in 0..=m {
            verts.push([-A / 2.0 + i as f64 * h, -A / 2.0 + j as f64 * h, T]);
        }
    }
    let id = |i: usize, j: usize| (j * (m + 1) + i) as u32;
    let mut tris = Vec::new();
    for j in 0..m {
        for i in 0..m {
            if (i + j) % 2 == 0 {
                tris.extend([
                    [id(i, j), id(i + 1, j), id(i + 1, j + 1)],
                    [id(i, j), id(i + 1, j + 1), id(i, j + 1)],
                ]);
            } else {
                tris.extend([
                    [id(i, j), id(i + 1, j), id(i, j + 1)],
                    [id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)],
                ]);
            }
        }
    }
    let mesh = facesim::mesh::Mesh::new(verts, tris);
    facesim::mesh::ply::write(
        &mesh,
        &dir.join("skin.ply"),
        facesim::mesh::ply::Encoding::BinaryLittleEndian,
    )
    .unwrap();
    let e = A / 2.0 - 0.5 * h;
    std::fs::write(
        dir.join("case.toml"),
        format!(
            r#"[ct]
path = "ct.nii.gz"
[skin]
path = "skin.ply"
[springs]
struts = false
[surface]
alpha = 0.0
beta = 1.0
parameterization = "planar"
movable = {{ box = {{ min = [{ne}, {ne}, 0.0], max = [{e}, {e}, 20.0] }} }}
[solve]
model = "{model}"
steps = 1
{k_c_key} = {k_c:e}
[[osteotomy]]
name = "slab"
region = {{ box = {{ min = [-100.0, -100.0, -100.0], max = [100.0, 100.0, 5.0] }} }}
translate = [0.0, 0.0, {LIFT}]
"#,
            ne = -e
        ),
    )
    .unwrap();
    mesh.vertices.len()
}

fn centre_lift(o: &facesim::commands::Outcome) -> (f64, f64) {
    let c = (0..o.skin.vertices.len())
        .min_by(|&a, &b| {
            let d = |i: usize| o.skin.vertices[i][0].powi(2) + o.skin.vertices[i][1].powi(2);
            d(a).total_cmp(&d(b))
        })
        .unwrap();
    // The series-integrated stiffness c of the centre's spring (all equal away from the edges).
    let s = o.report.springs.as_ref().unwrap();
    (
        o.face_post.vertices[c][2] - o.skin.vertices[c][2],
        s.stiffness[1],
    )
}

#[test]
fn koch1996_lift_gives_the_clamped_plate_deflection() {
    let d = tempfile::tempdir().unwrap();
    let k_c = 1e-6;
    write_case(d.path(), "koch1996", "koch_k_c", k_c);
    let o = facesim::commands::run(d.path(), None, &facesim::observe::Quiet).unwrap();
    let (w, c) = centre_lift(&o);
    // eq. 20 with k_i = Σ areas around i (3× the vertex's share) and a lift δ: a uniform load
    // q = 3 k_c c δ per unit area, lumped at the nodes.
    let q = 3.0 * k_c * c * LIFT;
    let exact = 0.00126532 * q * A.powi(4) / 1.0;
    println!(
        "koch1996 plate: centre lift {w:.6e} mm, clamped plate {exact:.6e} mm (c = {c:.2}), ratio {:.4}",
        w / exact
    );
    assert!((w / exact - 1.0).abs() < 0.03);
}

#[test]
fn equilibrium_lift_gives_the_clamped_plate_on_a_foundation() {
    let d = tempfile::tempdir().unwrap();
    // Springs and bending of the same order: 0.00126 κ a⁴ / D ≈ 1.
    let k_c = 1e-6;
    write_case(d.path(), "equilibrium", "k_c", k_c);
    let o = facesim::commands::run(d.path(), None, &facesim::observe::Quiet).unwrap();
    let (w, c) = centre_lift(&o);
    // Linearised: D∇⁴w + κ (w − δ) = 0 with κ = 3 k_c c per area (lumped springs): the clamped
    // plate on a Winkler foundation κ under q = κ δ. Reference: the C1 plate solver with that
    // foundation on the same mesh and clamped edges.
    let kappa = 3.0 * k_c * c;
    let uv: Vec<[f64; 2]> = o.skin.vertices.iter().map(|p| [p[0], p[1]]).collect();
    let fem = FemMesh::new(uv, o.skin.triangles.clone()).unwrap();
    let e = A / 2.0 - 1e-9;
    let rigid: Vec<bool> = o
        .skin
        .vertices
        .iter()
        .map(|p| p[0].abs() >= e || p[1].abs() >= e)
        .collect();
    let fixed = facesim::fem::assembly::rigid_dofs(&fem, &rigid);
    let mat = Material {
        alpha: [0.0; 3],
        beta: [1.0; 3],
        foundation: kappa,
    };
    let (k, f) = fem.assemble(&|_| mat, kappa * LIFT);
    let sys = System::new(fem.ndof(), k, &fixed).unwrap();
    let a = sys.solve(&[f], &[vec![0.0; fem.ndof()]]).remove(0);
    let centre = (0..fem.uv.len())
        .min_by(|&x, &y| {
            (fem.uv[x][0].powi(2) + fem.uv[x][1].powi(2))
                .total_cmp(&(fem.uv[y][0].powi(2) + fem.uv[y][1].powi(2)))
        })
        .unwrap();
    let reference = a[3 * centre];
    println!(
        "equilibrium plate: centre lift {w:.6e} mm, Winkler plate {reference:.6e} mm (κ = {kappa:.4}), ratio {:.4}",
        w / reference
    );
    assert!((w / reference - 1.0).abs() < 0.05);
    // The plate bends: its clamped edges hold the centre below the lift.
    assert!(w < 0.99 * LIFT && w > 0.1 * LIFT, "{w}");
}
