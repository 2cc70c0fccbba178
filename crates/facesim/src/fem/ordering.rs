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
    let vwgt: Vec<i32> = size.iter().map(|s| *s as i32).collect();
    let perm = metis_node_nd(xadj, adjncy, vwgt)?;
    // METIS: row i of the permuted matrix is row perm[i] of the original.
    let mut members = vec![Vec::new(); ns];
    for (j, s) in of.iter().enumerate() {
        members[*s].push(j);
    }
    let mut forward = Vec::with_capacity(n);
    for &s in &perm {
        forward.extend_from_slice(members.get(s)?);
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

/// METIS's nested dissection of a graph (CSR, vertex weights): `perm[new] = old`.
fn metis_node_nd(
    mut xadj: Vec<i32>,
    mut adjncy: Vec<i32>,
    mut vwgt: Vec<i32>,
) -> Option<Vec<usize>> {
    let ns = vwgt.len();
    let mut nvtxs = i32::try_from(ns).ok()?;
    let mut perm = vec![0i32; ns];
    let mut iperm = vec![0i32; ns];
    let mut options = [0i32; metis_sys::METIS_NOPTIONS as usize];
    // METIS seeds its random generator per call, but the generator's state is process-global
    // (GKlib): two calls on different threads (tests, a library caller running cases in
    // parallel) would perturb each other's orderings and so the rounding of every solve. One call
    // at a time keeps each ordering a function of its graph alone (docs/guide/uncertainty.md: the same
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
    perm.iter().map(|p| usize::try_from(*p).ok()).collect()
}

/// A nested-dissection ordering of a tetrahedral mesh's nodes, computed once per mesh and
/// expanded to the free DOFs of any holds on it (`dofs`): the run's solve, its tearing rounds,
/// every uncertainty sample and each reduced model's reference factor share it, where each
/// used to order its own free DOFs (0.3–0.4 s a call on the real CT, one call at a time).
///
/// The graph is the nodes with a free DOF in the run's holds (`solved`): nodes held whole
/// (the bone) would count in METIS's balance and separators and then drop out of every factor
/// (with them the real CT's factor grew and its solve took longer). Other holds on the mesh
/// differ little: a node they hold whole drops out (a nested-dissection ordering stays one
/// when vertices are removed), and one they free that the run held (tissue lifted off the
/// bone) goes last, as a separator would.
pub(crate) struct NodeOrder {
    /// Per node, its place in the ordering; u32::MAX for a node outside the graph.
    rank: Vec<u32>,
}

impl NodeOrder {
    /// The ordering of the graph of the `solved` nodes of `tets` (nodes sharing a tetrahedron
    /// are neighbours); None when METIS fails or the mesh is too small to be worth it (the
    /// caller orders the DOFs itself).
    pub(crate) fn of_tets(solved: &[bool], tets: &[[u32; 4]]) -> Option<NodeOrder> {
        let nodes = solved.len();
        // The graph's vertices: the solved nodes, numbered in node order.
        let mut vertex = vec![u32::MAX; nodes];
        let mut count_v = 0u32;
        for (v, s) in vertex.iter_mut().zip(solved) {
            if *s {
                *v = count_v;
                count_v += 1;
            }
        }
        let nv = count_v as usize;
        if 3 * nv < 64 {
            return None;
        }
        let vertex_of = |a: u32| vertex.get(a as usize).copied().filter(|v| *v != u32::MAX);
        let mut count = vec![0usize; nv + 1];
        for t in tets {
            for a in t.iter().filter_map(|a| vertex_of(*a)) {
                count[a as usize + 1] += 3;
            }
        }
        for i in 0..nv {
            count[i + 1] += count[i];
        }
        let mut next = count.clone();
        let mut adj = vec![u32::MAX; count[nv]];
        for t in tets {
            let v = t.map(vertex_of);
            for (i, a) in v.iter().enumerate() {
                let Some(a) = a else { continue };
                for (j, b) in v.iter().enumerate() {
                    if i != j {
                        // A held neighbour leaves its slot empty (u32::MAX, skipped below).
                        adj[next[*a as usize]] = b.unwrap_or(u32::MAX);
                        next[*a as usize] += 1;
                    }
                }
            }
        }
        let mut xadj: Vec<i32> = Vec::with_capacity(nv + 1);
        let mut adjncy: Vec<i32> = Vec::with_capacity(adj.len() / 4);
        xadj.push(0);
        for v in 0..nv {
            let row = &mut adj[count[v]..count[v + 1]];
            row.sort_unstable();
            let mut last = None;
            for &b in row.iter().filter(|b| **b != u32::MAX) {
                if last != Some(b) {
                    adjncy.push(i32::try_from(b).ok()?);
                    last = Some(b);
                }
            }
            xadj.push(i32::try_from(adjncy.len()).ok()?);
        }
        let perm = metis_node_nd(xadj, adjncy, vec![1; nv])?;
        let mut node_of = Vec::with_capacity(nv);
        node_of.extend((0..nodes).filter(|n| solved[*n]));
        let mut rank = vec![u32::MAX; nodes];
        for (new, &old) in perm.iter().enumerate() {
            *rank.get_mut(*node_of.get(old)?)? = u32::try_from(new).ok()?;
        }
        Some(NodeOrder { rank })
    }

    /// The ordering of the free DOFs `free` (global DOF 3 node + component, one per column):
    /// `(forward, inverse)` as [`nested_dissection`] gives it, the DOFs of nodes outside the
    /// graph last; None when a DOF's node is not in the mesh.
    pub(crate) fn dofs(&self, free: &[usize]) -> Option<(Vec<usize>, Vec<usize>)> {
        let mut key = Vec::with_capacity(free.len());
        for (col, dof) in free.iter().enumerate() {
            let r = u64::from(*self.rank.get(dof / 3)?);
            // Outside the graph: after every ranked node, in DOF order.
            let k = if r == u64::from(u32::MAX) {
                3 * r + *dof as u64
            } else {
                3 * r + (dof % 3) as u64
            };
            key.push((k, col));
        }
        key.sort_unstable();
        let forward: Vec<usize> = key.into_iter().map(|(_, col)| col).collect();
        let mut inverse = vec![0usize; free.len()];
        for (new, &old) in forward.iter().enumerate() {
            inverse[old] = new;
        }
        Some((forward, inverse))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::cholesky::{MeshAnalyses, Ordering, Pattern};
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
        let amd = Pattern::analyse_with(a.symbolic(), Ordering::Amd, &[]).unwrap();
        let nd = Pattern::analyse_with(a.symbolic(), Ordering::NestedDissection, &[]).unwrap();
        assert!(
            (nd.factor_nnz() as f64) < 0.9 * amd.factor_nnz() as f64,
            "nested dissection {} vs AMD {} factor entries",
            nd.factor_nnz(),
            amd.factor_nnz()
        );
    }

    /// The mesh's node ordering serves holds other than the ones it was made for: the DOFs of
    /// a node held there drop out, those of a node freed since come last, every free DOF once;
    /// its factor fills about as little as the free DOFs' own nested dissection; and a pattern
    /// analysed in it once is not analysed again.
    #[test]
    fn a_node_ordering_serves_other_holds_and_fills_as_little() {
        let m = 14;
        let nodes = m * m * m;
        // Made for: the bottom layer (x = 0) held whole.
        let solved: Vec<bool> = (0..nodes).map(|n| n / (m * m) != 0).collect();
        let order = NodeOrder::of_tets(&solved, &crate::mesh::kuhn_grid(m)).unwrap();
        // Used for: also the top layer held, one component of every node in the middle layer
        // held (sliding), and two bottom nodes freed.
        let freed = [5usize, 40];
        let free: Vec<usize> = (0..3 * nodes)
            .filter(|d| {
                let (n, c) = (d / 3, d % 3);
                let layer = n / (m * m);
                (layer != 0 || freed.contains(&n)) && layer != m - 1 && !(layer == m / 2 && c == 0)
            })
            .collect();
        let (fwd, inv) = order.dofs(&free).unwrap();
        let mut seen = vec![false; free.len()];
        for (new, &old) in fwd.iter().enumerate() {
            assert!(!seen[old], "column {old} twice");
            seen[old] = true;
            assert_eq!(inv[old], new);
        }
        assert!(seen.iter().all(|s| *s));
        let last: Vec<usize> = fwd[fwd.len() - 6..].iter().map(|c| free[*c] / 3).collect();
        assert_eq!(last, [5, 5, 5, 40, 40, 40], "the freed nodes' DOFs go last");
        // The free block of the grid's stiffness pattern, in both orderings.
        let full = grid(m);
        let mut at = vec![usize::MAX; 3 * nodes];
        for (i, d) in free.iter().enumerate() {
            at[*d] = i;
        }
        let mut t = Vec::new();
        for c in 0..full.ncols() {
            for r in full.symbolic().row_idx_of_col(c) {
                if at[r] != usize::MAX && at[c] != usize::MAX {
                    t.push(Triplet::new(at[r].max(at[c]), at[r].min(at[c]), 1.0));
                }
            }
        }
        let a = SparseColMat::try_new_from_triplets(free.len(), free.len(), &t).unwrap();
        let own = Pattern::analyse_with(a.symbolic(), Ordering::NestedDissection, &[]).unwrap();
        let mesh = MeshAnalyses::new(order);
        let shared = Pattern::analyse_with(a.symbolic(), Ordering::Nodes(&mesh), &free).unwrap();
        // The same pattern again is the same analysis, not a new one; another pattern (one DOF
        // fewer) is its own.
        let again = Pattern::analyse_with(a.symbolic(), Ordering::Nodes(&mesh), &free).unwrap();
        assert!(again.is(&shared));
        let fewer = SparseColMat::try_new_from_triplets(
            free.len() - 1,
            free.len() - 1,
            &t.iter()
                .filter(|e| e.row < free.len() - 1)
                .copied()
                .collect::<Vec<_>>(),
        )
        .unwrap();
        let other = Pattern::analyse_with(
            fewer.symbolic(),
            Ordering::Nodes(&mesh),
            &free[..free.len() - 1],
        )
        .unwrap();
        assert!(!other.is(&shared));
        assert!(other.factor_nnz() < shared.factor_nnz());
        let amd = Pattern::analyse_with(a.symbolic(), Ordering::Amd, &[]).unwrap();
        let (own, shared, amd) = (own.factor_nnz(), shared.factor_nnz(), amd.factor_nnz());
        assert!(
            (shared as f64) < 1.15 * own as f64 && (shared as f64) < 0.9 * amd as f64,
            "factor entries: shared node ordering {shared}, own nested dissection {own}, AMD {amd}"
        );
    }
}
