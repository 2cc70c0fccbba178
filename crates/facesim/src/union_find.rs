//! Disjoint sets (union–find) for the connected-component passes: skin-mesh pieces, patches of
//! spring misses, voxel-run components, the singularity check's mesh pieces and the study's
//! lattice. Union by rank and path compression keep every operation near O(1).
//!
//! The balancing decides which tree root survives a union, but callers print and key on a set's
//! element, so each set carries a *representative* that does not depend on the balancing:
//! `union(a, b)` keeps `a`'s. That is the element the naive `parent[root(b)] = root(a)` would
//! leave as root, so messages that name it are unchanged.

/// Disjoint sets over `0..n` (n < 2³²; indices are stored as u32 to keep voxel-run passes small).
#[derive(Clone, Debug)]
pub struct UnionFind {
    parent: Vec<u32>,
    rank: Vec<u8>,
    /// The representative of the set rooted here (meaningful at roots only).
    rep: Vec<u32>,
}

impl UnionFind {
    /// `n` singleton sets, each its own representative.
    pub fn new(n: usize) -> Self {
        assert!(
            u32::try_from(n).is_ok(),
            "union-find over {n} elements: at most 2^32 - 1"
        );
        let ids: Vec<u32> = (0..n as u32).collect();
        UnionFind {
            parent: ids.clone(),
            rank: vec![0; n],
            rep: ids,
        }
    }

    pub fn len(&self) -> usize {
        self.parent.len()
    }

    pub fn is_empty(&self) -> bool {
        self.parent.is_empty()
    }

    /// The tree root of `x`, pointing every node on the way straight at it.
    fn root(&mut self, x: usize) -> usize {
        let mut r = x;
        while self.parent[r] as usize != r {
            r = self.parent[r] as usize;
        }
        let mut y = x;
        while self.parent[y] as usize != r {
            let next = self.parent[y] as usize;
            self.parent[y] = r as u32;
            y = next;
        }
        r
    }

    /// The representative of `x`'s set (see the module doc).
    pub fn find(&mut self, x: usize) -> usize {
        let r = self.root(x);
        self.rep[r] as usize
    }

    /// Whether `a` and `b` are in one set.
    pub fn same(&mut self, a: usize, b: usize) -> bool {
        self.root(a) == self.root(b)
    }

    /// Merge the sets of `a` and `b`; the merged set keeps `a`'s representative. Returns
    /// whether they were apart.
    pub fn union(&mut self, a: usize, b: usize) -> bool {
        let (ra, rb) = (self.root(a), self.root(b));
        if ra == rb {
            return false;
        }
        let keep = self.rep[ra];
        let (hi, lo) = if self.rank[ra] >= self.rank[rb] {
            (ra, rb)
        } else {
            (rb, ra)
        };
        self.parent[lo] = hi as u32;
        if self.rank[hi] == self.rank[lo] {
            self.rank[hi] += 1;
        }
        self.rep[hi] = keep;
        true
    }

    /// A label per element, the sets numbered 0, 1, … in the order their smallest element
    /// appears, and the number of sets.
    pub fn labels(&mut self) -> (Vec<u32>, usize) {
        let n = self.len();
        let mut of_root = vec![u32::MAX; n];
        let mut next = 0u32;
        let labels = (0..n)
            .map(|x| {
                let r = self.root(x);
                if of_root[r] == u32::MAX {
                    of_root[r] = next;
                    next += 1;
                }
                of_root[r]
            })
            .collect();
        (labels, next as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Labels by flooding the edge graph from each unlabelled element in index order.
    fn naive_labels(n: usize, edges: &[(usize, usize)]) -> (Vec<u32>, usize) {
        let mut nb = vec![Vec::new(); n];
        for &(a, b) in edges {
            nb[a].push(b);
            nb[b].push(a);
        }
        let mut label = vec![u32::MAX; n];
        let mut count = 0;
        for s in 0..n {
            if label[s] != u32::MAX {
                continue;
            }
            let mut stack = vec![s];
            label[s] = count;
            while let Some(x) = stack.pop() {
                for &y in &nb[x] {
                    if label[y] == u32::MAX {
                        label[y] = count;
                        stack.push(y);
                    }
                }
            }
            count += 1;
        }
        (label, count as usize)
    }

    /// The unbalanced union the callers used before: `b`'s root is hung under `a`'s.
    fn naive_roots(n: usize, edges: &[(usize, usize)]) -> Vec<usize> {
        let mut p: Vec<usize> = (0..n).collect();
        fn root(p: &[usize], mut x: usize) -> usize {
            while p[x] != x {
                x = p[x];
            }
            x
        }
        for &(a, b) in edges {
            let (ra, rb) = (root(&p, a), root(&p, b));
            p[rb] = ra;
        }
        (0..n).map(|x| root(&p, x)).collect()
    }

    #[test]
    fn singletons_then_merges() {
        let mut u = UnionFind::new(5);
        assert_eq!(u.len(), 5);
        assert!(!u.same(0, 1));
        assert_eq!(u.labels(), (vec![0, 1, 2, 3, 4], 5));
        assert!(u.union(3, 1));
        assert!(!u.union(1, 3));
        assert!(u.union(4, 0));
        assert!(u.same(1, 3) && u.same(0, 4) && !u.same(0, 1));
        assert_eq!((u.find(1), u.find(0)), (3, 4));
        assert_eq!(u.labels(), (vec![0, 1, 2, 1, 0], 3));
        assert!(UnionFind::new(0).is_empty());
        assert_eq!(UnionFind::new(0).labels(), (vec![], 0));
    }

    #[test]
    fn representative_survives_rank_balancing() {
        // {0, 1, 2} outranks {3}; the merged set still answers with 3, the first argument's.
        let mut u = UnionFind::new(4);
        u.union(0, 1);
        u.union(0, 2);
        u.union(3, 2);
        assert!((0..4).all(|x| u.find(x) == 3));
    }

    #[test]
    fn long_chain_is_flattened() {
        let n = 100_000;
        let mut u = UnionFind::new(n);
        for i in 1..n {
            u.union(i, i - 1);
        }
        assert_eq!(u.find(0), n - 1);
        assert!(u.rank.iter().all(|&r| r <= 17), "rank stays logarithmic");
        assert_eq!(u.labels().1, 1);
    }

    proptest! {
        #[test]
        fn matches_naive_labelling(
            (n, edges) in (1usize..60).prop_flat_map(|n| {
                (Just(n), proptest::collection::vec((0..n, 0..n), 0..120))
            })
        ) {
            let mut u = UnionFind::new(n);
            for &(a, b) in &edges {
                u.union(a, b);
            }
            prop_assert_eq!(u.labels(), naive_labels(n, &edges));
            let roots = naive_roots(n, &edges);
            for x in 0..n {
                prop_assert_eq!(u.find(x), roots[x]);
                for y in 0..n {
                    prop_assert_eq!(u.same(x, y), roots[x] == roots[y]);
                }
            }
        }
    }
}
