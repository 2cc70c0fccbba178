//! The skin's largest displacement jump: over the face's edges, the change of displacement
//! between the edge's two vertices ÷ the edge's length (report.json `displacement.largest_jump`).
//! Skin that follows a smooth field has a small figure (a rigid move: 0; a uniform stretch: the
//! strain); a crease or a tear — one vertex moving and its neighbour staying — gives the move ÷
//! the edge, about 1 for a tear as wide as the face's edges.

use crate::mesh::Mesh;
use crate::vec3::{norm, sub};
use serde::{Deserialize, Serialize};

/// The edge where the displacement changes most per mm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Jump {
    /// |u(a) − u(b)| ÷ |a − b| on the face before (mm per mm).
    pub per_mm: f64,
    /// The edge's vertices (face_pre's indices) and their positions before (LPS mm).
    pub vertices: [usize; 2],
    pub at: [[f64; 3]; 2],
    /// Each vertex's displacement magnitude (mm) and the edge's length (mm).
    pub moves_mm: [f64; 2],
    pub edge_mm: f64,
    /// Edges whose jump exceeds 0.5 per mm.
    pub edges_over_half: usize,
}

/// The largest jump of the face `pre` moved to `post` (same vertex order); None for a face
/// without edges.
pub(crate) fn largest(pre: &Mesh, post: &[[f64; 3]]) -> Option<Jump> {
    let u: Vec<[f64; 3]> = pre
        .vertices
        .iter()
        .zip(post)
        .map(|(a, b)| sub(*b, *a))
        .collect();
    // Each edge once (an interior edge belongs to two triangles).
    let mut edges: Vec<(usize, usize)> = pre
        .triangles
        .iter()
        .flat_map(|t| {
            (0..3).map(move |k| {
                let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
                (a.min(b), a.max(b))
            })
        })
        .collect();
    edges.sort_unstable();
    edges.dedup();
    let mut best: Option<Jump> = None;
    let mut over = 0;
    for (a, b) in edges {
        let edge = norm(sub(pre.vertices[a], pre.vertices[b]));
        if edge <= 1e-9 {
            continue;
        }
        let per_mm = norm(sub(u[a], u[b])) / edge;
        over += usize::from(per_mm > 0.5);
        if best.as_ref().is_none_or(|j| per_mm > j.per_mm) {
            best = Some(Jump {
                per_mm,
                vertices: [a, b],
                at: [pre.vertices[a], pre.vertices[b]],
                moves_mm: [norm(u[a]), norm(u[b])],
                edge_mm: edge,
                edges_over_half: 0,
            });
        }
    }
    best.map(|j| Jump {
        edges_over_half: over,
        ..j
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4 × 4 grid of unit squares (two triangles each) in the plane z = 0.
    fn grid() -> Mesh {
        let mut m = Mesh::default();
        for j in 0..5 {
            for i in 0..5 {
                m.vertices.push([i as f64, j as f64, 0.0]);
            }
        }
        for j in 0..4u32 {
            for i in 0..4u32 {
                let v = j * 5 + i;
                m.triangles.push([v, v + 1, v + 6]);
                m.triangles.push([v, v + 6, v + 5]);
            }
        }
        m
    }

    #[test]
    fn a_rigid_move_has_no_jump_and_a_stretch_its_strain() {
        let m = grid();
        let moved: Vec<[f64; 3]> = m
            .vertices
            .iter()
            .map(|p| [p[0] + 3.0, p[1] - 2.0, p[2] + 1.0])
            .collect();
        assert!(largest(&m, &moved).unwrap().per_mm < 1e-12);
        // x stretched by 10 %: the largest jump is along x, 0.1 per mm.
        let stretched: Vec<[f64; 3]> = m
            .vertices
            .iter()
            .map(|p| [1.1 * p[0], p[1], p[2]])
            .collect();
        let j = largest(&m, &stretched).unwrap();
        assert!((j.per_mm - 0.1).abs() < 1e-12, "{j:?}");
        assert_eq!(j.edges_over_half, 0);
    }

    #[test]
    fn one_vertex_moving_alone_is_a_tear_of_its_move_over_its_edge() {
        let m = grid();
        let mut post = m.vertices.clone();
        // The centre vertex (2, 2) moves 2 mm along z; its neighbours stay.
        post[12][2] += 2.0;
        let j = largest(&m, &post).unwrap();
        assert!((j.per_mm - 2.0).abs() < 1e-12, "{j:?}");
        assert!(
            j.vertices.contains(&12) && j.moves_mm.contains(&2.0),
            "{j:?}"
        );
        // Its six edges in this triangulation: four of length 1 (jump 2), two diagonals (√2).
        assert_eq!(j.edges_over_half, 6);
    }
}
