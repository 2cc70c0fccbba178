//! Fill-reducing orderings for the sparse Cholesky factor.
//!
//! faer's approximate minimum degree (AMD) is good for the C1 surface systems, which are
//! two-dimensional. For the volumetric model's three-dimensional meshes nested dissection
//! (George 1973; METIS, Karypis & Kumar 1998) does much better: separators of a 3D mesh of N
//! nodes have ~N^(2/3) nodes, the factor ~N^(4/3) entries, against the larger fill AMD's local
//! greedy choices leave. METIS (Apache-2.0, built from source by `metis-sys`) computes it.
//!
//! The matrix's DOFs come in groups with the same sparsity pattern (the three DOFs of a node),
//! so the ordering is computed on the graph of those groups ("supervariables") weighted by their
//! size, then expanded: four to nine times smaller a graph, and each node's DOFs stay together.

use faer::sparse::SymbolicSparseColMatRef;

/// The symmetric graph of a lower-triangle pattern: per column, its neighbours (no diagonal),
/// ascending.
fn symmetric_graph(lower: SymbolicSparseColMatRef<'_, usize>) -> (Vec<usize>, Vec<usize>) {
    let n = lower.ncols();
    let mut count = vec![0usize; n + 1];
    for c in 0..n {
        for r in lower.row_idx_of_col(c) {
            if r != c {
                count[r + 1] += 1;
                count[c + 1] += 1;
            }
        }
    }
    for i in 0..n {
        count[i + 1] += count[i];
    }
    let mut next = count.clone();
    let mut adj = vec![0usize; count[n]];
    // Columns in ascending order: each list receives its smaller neighbours (as a row of an
    // earlier column) before its larger ones (its own column), both ascending when the
    // pattern's rows are sorted; sort anyway in case they are not.
    for c in 0..n {
        for r in lower.row_idx_of_col(c) {
            if r != c {
                adj[next[c]] = r;
                next[c] += 1;
                adj[next[r]] = c;
                next[r] += 1;
            }
        }
    }
    for i in 0..n {
        adj[count[i]..count[i + 1]].sort_unstable();
    }
    (count, adj)
}

/// Consecutive DOFs whose closed neighbourhoods (neighbours plus themselves) are equal form one
/// supervariable. Returns each DOF's supervariable and the supervariables' sizes.
fn supervariables(ptr: &[usize], adj: &[usize]) -> (Vec<usize>, Vec<usize>) {
    let n = ptr.len() - 1;
    // For adjacent a, b: N(a) ∪ {a} == N(b) ∪ {b} ⇔ b ∈ N(a) and N(a) \ {b} == N(b) \ {a}.
    let closed_equal = |a: usize, b: usize| {
        let (na, nb) = (&adj[ptr[a]..ptr[a + 1]], &adj[ptr[b]..ptr[b + 1]]);
        na.len() == nb.len()
            && na.binary_search(&b).is_ok()
            && na
                .iter()
                .filter(|x| **x != b)
                .eq(nb.iter().filter(|x| **x != a))
    };
    let mut of = vec![0usize; n];
    let mut size: Vec<usize> = Vec::new();
    for j in 0..n {
        if j > 0 && closed_equal(j - 1, j) {
            of[j] = of[j - 1];
            if let Some(last) = size.last_mut() {
                *last += 1;
            }
        } else {
            of[j] = size.len();
            size.push(1);
        }
    }
    (of, size)
}

/// A nested-dissection ordering of the lower-triangle pattern: `(forward, inverse)` with
/// `forward[new] = old`, as faer's `PermRef` takes it. None when METIS fails (the caller falls
/// back to AMD) or the matrix is too small to be worth it.
pub(crate) fn nested_dissection(
    lower: SymbolicSparseColMatRef<'_, usize>,
) -> Option<(Vec<usize>, Vec<usize>)> {
    let n = lower.ncols();
    if n < 64 {
        return None;
    }
    let (ptr, adj) = symmetric_graph(lower);
    let (of, size) = supervariables(&ptr, &adj);
    let ns = size.len();
    // The supervariable graph: the neighbours of a supervariable's first DOF, mapped.
    let mut first = vec![usize::MAX; ns];
    for (j, s) in of.iter().enumerate() {
        if first[*s] == usize::MAX {
            first[*s] = j;
        }
    }
    let mut xadj: Vec<i32> = Vec::with_capacity(ns + 1);
    let mut adjncy: Vec<i32> = Vec::new();
    xadj.push(0);
    let mut seen = vec![usize::MAX; ns];
    for (s, &j) in first.iter().enumerate() {
        seen[s] = s;
        for &r in &adj[ptr[j]..ptr[j + 1]] {
            let t = of[r];
            if seen[t] != s {
                seen[t] = s;
                adjncy.push(i32::try_from(t).ok()?);
            }
        }
        xadj.push(i32::try_from(adjncy.len()).ok()?);
    }
    let mut vwgt: Vec<i32> = size.iter().map(|s| *s as i32).collect();
    let mut nvtxs = i32::try_from(ns).ok()?;
    let mut perm = vec![0i32; ns];
    let mut iperm = vec![0i32; ns];
    let mut options = [0i32; metis_sys::METIS_NOPTIONS as usize];
    // METIS seeds its random generator per call, but the generator's state is process-global
    // (GKlib): two calls on different threads (tests, a library caller running cases in
    // parallel) would perturb each other's orderings and so the rounding of every solve. One call
    // at a time keeps each ordering a function of its graph alone (docs/uncertainty.md: the same
    // seed writes the same bytes). A poisoned lock only means another call panicked.
    static METIS: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one_at_a_time = METIS.lock().unwrap_or_else(|p| p.into_inner());
    // SAFETY: METIS reads nvtxs + 1 offsets, the adjacency they span and nvtxs weights, and writes
    // nvtxs entries into perm and iperm; every buffer has those lengths and outlives the call.
    let status = unsafe {
        metis_sys::METIS_SetDefaultOptions(options.as_mut_ptr());
        options[metis_sys::moptions_et_METIS_OPTION_NUMBERING as usize] = 0;
        metis_sys::METIS_NodeND(
            &mut nvtxs,
            xadj.as_mut_ptr(),
            adjncy.as_mut_ptr(),
            vwgt.as_mut_ptr(),
            options.as_mut_ptr(),
            perm.as_mut_ptr(),
            iperm.as_mut_ptr(),
        )
    };
    if status != metis_sys::rstatus_et_METIS_OK {
        return None;
    }
    // METIS: row i of the permuted matrix is row perm[i] of the original.
    let mut members = vec![Vec::new(); ns];
    for (j, s) in of.iter().enumerate() {
        members[*s].push(j);
    }
    let mut forward = Vec::with_capacity(n);
    for &s in &perm {
        forward.extend_from_slice(members.get(usize::try_from(s).ok()?)?);
    }
    if forward.len() != n {
        return None;
    }
    let mut inverse = vec![0usize; n];
    for (new, &old) in forward.iter().enumerate() {
        inverse[old] = new;
    }
    Some((forward, inverse))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::cholesky::{Ordering, Pattern};
    use faer::sparse::{SparseColMat, Triplet};

    /// The lower pattern of a 3-DOF-per-node matrix on an m³ grid of nodes coupled to their 26
    /// neighbours (the stencil of a hexahedral or tetrahedral elasticity mesh).
    fn grid(m: usize) -> SparseColMat<usize, f64> {
        let id = |x: usize, y: usize, z: usize| (x * m + y) * m + z;
        let mut t = Vec::new();
        for x in 0..m {
            for y in 0..m {
                for z in 0..m {
                    for dx in 0..2 {
                        for dy in 0..2 {
                            for dz in 0..2 {
                                let (a, b, c) = (x + dx, y + dy, z + dz);
                                if a < m && b < m && c < m {
                                    let (i, j) = (id(a, b, c), id(x, y, z));
                                    for r in 0..3 {
                                        for s in 0..3 {
                                            let (gi, gj) = (3 * i + r, 3 * j + s);
                                            if gi >= gj {
                                                t.push(Triplet::new(gi, gj, 1.0));
                                            }
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        let n = 3 * m * m * m;
        SparseColMat::try_new_from_triplets(n, n, &t).unwrap()
    }

    #[test]
    fn nested_dissection_is_a_permutation_keeping_nodes_together() {
        let a = grid(6);
        let (fwd, inv) = nested_dissection(a.symbolic()).unwrap();
        let n = a.ncols();
        let mut seen = vec![false; n];
        for (new, &old) in fwd.iter().enumerate() {
            assert!(!seen[old]);
            seen[old] = true;
            assert_eq!(inv[old], new);
        }
        // The three DOFs of a node are one supervariable: consecutive in the new order.
        for k in (0..n).step_by(3) {
            assert_eq!(fwd[k] / 3, fwd[k + 2] / 3);
            assert_eq!(fwd[k] % 3, 0);
        }
    }

    /// The reason it exists: on a 3D mesh nested dissection leaves a sparser factor than AMD.
    #[test]
    fn nested_dissection_fills_less_than_amd_in_3d() {
        let a = grid(16);
        let amd = Pattern::analyse_with(a.symbolic(), Ordering::Amd).unwrap();
        let nd = Pattern::analyse_with(a.symbolic(), Ordering::NestedDissection).unwrap();
        assert!(
            (nd.factor_nnz() as f64) < 0.9 * amd.factor_nnz() as f64,
            "nested dissection {} vs AMD {} factor entries",
            nd.factor_nnz(),
            amd.factor_nnz()
        );
    }
}
