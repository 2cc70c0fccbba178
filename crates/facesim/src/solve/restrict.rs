//! The exact restriction of the solve to the skin piece the bone moves can reach, and the
//! mapping of C1 DOFs between that piece and the whole face.

use super::problem::Solution;
use crate::fem::assembly::FemMesh;
use crate::mesh::Mesh;
use crate::springs::SpringSet;
use std::collections::HashMap;

/// The skin the bone moves can reach: the movable vertices, their rigid neighbours (so every free
/// DOF keeps its whole fitting neighbourhood) and every triangle touching them. Triangles whose
/// twelve DOFs are all fixed add nothing to the equilibrium of the free ones, so solving on this
/// piece is exact; on the real CT it is a fraction of the face (docs/design/pipeline.md §5).
pub(super) struct Restriction {
    pub(super) skin: Mesh,
    pub(super) springs: SpringSet,
    pub(super) rigid: Vec<bool>,
    /// Sub-mesh vertex → full-mesh vertex (increasing, so edge orientation is preserved).
    pub(super) to_full: Vec<usize>,
}

impl Restriction {
    pub(super) fn new(skin: &Mesh, springs: &SpringSet, rigid: &[bool]) -> Option<Restriction> {
        let nv = skin.vertices.len();
        let mut near: Vec<bool> = rigid.iter().map(|r| !r).collect();
        for t in &skin.triangles {
            if t.iter().any(|&v| !rigid[v as usize]) {
                for &v in t {
                    near[v as usize] = true;
                }
            }
        }
        let keep: Vec<&[u32; 3]> = skin
            .triangles
            .iter()
            .filter(|t| t.iter().any(|&v| near[v as usize]))
            .collect();
        if keep.len() == skin.triangles.len() || keep.is_empty() {
            return None;
        }
        let mut used = vec![false; nv];
        for t in &keep {
            for &v in *t {
                used[v as usize] = true;
            }
        }
        let to_full: Vec<usize> = (0..nv).filter(|&v| used[v]).collect();
        let mut to_sub = vec![u32::MAX; nv];
        for (i, &v) in to_full.iter().enumerate() {
            to_sub[v] = i as u32;
        }
        let mut sub = Mesh::new(
            to_full.iter().map(|&v| skin.vertices[v]).collect(),
            keep.iter().map(|t| t.map(|v| to_sub[v as usize])).collect(),
        );
        sub.vertex_columns = skin
            .vertex_columns
            .iter()
            .map(|c| crate::mesh::Column {
                name: c.name.clone(),
                values: to_full.iter().map(|&v| c.values[v]).collect(),
            })
            .collect();
        let sub_springs = SpringSet {
            attachment_of: to_full.iter().map(|&v| springs.attachment_of[v]).collect(),
            attachments: springs.attachments.clone(),
            springs: springs
                .springs
                .iter()
                .filter(|s| used[s.skin])
                .map(|s| crate::springs::Spring {
                    skin: to_sub[s.skin] as usize,
                    ..s.clone()
                })
                .collect(),
            k: to_full.iter().map(|&v| springs.k[v]).collect(),
            misses: Vec::new(),
        };
        Some(Restriction {
            skin: sub,
            springs: sub_springs,
            rigid: to_full.iter().map(|&v| rigid[v]).collect(),
            to_full,
        })
    }

    /// Per edge of the piece's C1 mesh, its edge in the whole face's mesh.
    pub(super) fn edges_to_full(&self, fem: &FemMesh, piece: &FemMesh) -> Vec<Option<usize>> {
        let edge_index: HashMap<[u32; 2], usize> =
            fem.edges.iter().enumerate().map(|(i, e)| (*e, i)).collect();
        piece
            .edges
            .iter()
            .map(|ed| {
                let full = [
                    self.to_full[ed[0] as usize] as u32,
                    self.to_full[ed[1] as usize] as u32,
                ];
                edge_index.get(&full).copied()
            })
            .collect()
    }

    /// The piece's DOFs of x, y, z taken from the whole face's `a` (`edges` from
    /// `edges_to_full`).
    pub(super) fn piece_dofs(
        &self,
        fem: &FemMesh,
        a: &[Vec<f64>; 3],
        piece: &FemMesh,
        edges: &[Option<usize>],
    ) -> [Vec<f64>; 3] {
        let (sub, full) = (piece.dofs(), fem.dofs());
        [0, 1, 2].map(|c| {
            let mut x = vec![0.0; sub.ndof()];
            for (i, &g) in self.to_full.iter().enumerate() {
                x[sub.vertex(i)].copy_from_slice(&a[c][full.vertex(g)]);
            }
            for (e, fe) in edges.iter().enumerate() {
                if let Some(fe) = fe {
                    x[sub.edge(e)] = a[c][full.edge(*fe)];
                }
            }
            x
        })
    }

    /// Write the piece's solved free DOFs back into the whole face's `a`. Only the free DOFs
    /// come from the piece: fixed ones keep the whole face's preload (the piece's fits at its
    /// edge see a truncated neighbourhood).
    pub(super) fn merge_free(
        &self,
        fem: &FemMesh,
        a: &mut [Vec<f64>; 3],
        s: &Solution,
        edges: &[Option<usize>],
    ) {
        let (sub, full) = (s.fem.dofs(), fem.dofs());
        for c in 0..3 {
            for (i, &g) in self.to_full.iter().enumerate() {
                if !self.rigid[i] {
                    a[c][full.vertex(g)].copy_from_slice(&s.a[c][sub.vertex(i)]);
                }
            }
            for (e, ed) in s.fem.edges.iter().enumerate() {
                if self.rigid[ed[0] as usize] && self.rigid[ed[1] as usize] {
                    continue;
                }
                if let Some(fe) = edges[e] {
                    a[c][full.edge(fe)] = s.a[c][sub.edge(e)];
                }
            }
        }
    }
}
