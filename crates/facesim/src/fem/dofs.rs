//! The global C1 DOF numbering (Koch eq. 11, 15–16), the one place that defines it: vertex i
//! owns 3i (value), 3i+1 (∂u), 3i+2 (∂v); edge e owns 3·nv + e (the cross-boundary derivative
//! along the edge's global normal, eq. 11). Values first, so a vertex's three DOFs are adjacent
//! and the edge DOFs follow all vertices.

use std::ops::Range;

/// The DOF numbering of a C1 mesh with `nv` vertices and `ne` edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dofs {
    pub nv: usize,
    pub ne: usize,
}

/// What a global DOF belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Owner {
    Vertex(usize),
    Edge(usize),
}

impl Dofs {
    pub fn new(nv: usize, ne: usize) -> Dofs {
        Dofs { nv, ne }
    }

    /// Number of DOFs.
    pub fn ndof(&self) -> usize {
        3 * self.nv + self.ne
    }

    /// The value DOF of vertex i.
    pub fn value(&self, i: usize) -> usize {
        3 * i
    }

    /// Vertex i's value, ∂u and ∂v DOFs.
    pub fn vertex(&self, i: usize) -> Range<usize> {
        3 * i..3 * i + 3
    }

    /// Edge e's cross-boundary derivative DOF.
    pub fn edge(&self, e: usize) -> usize {
        3 * self.nv + e
    }

    /// The vertex or edge owning DOF g.
    pub fn owner(&self, g: usize) -> Owner {
        if g < 3 * self.nv {
            Owner::Vertex(g / 3)
        } else {
            Owner::Edge(g - 3 * self.nv)
        }
    }
}
