//! The C1 triangular surface finite element model (Koch et al. 1996 §3–4.3).

pub mod assembly;
pub(crate) mod block_sparse;
pub mod cholesky;
pub mod dofs;
pub mod element;
pub(crate) mod jet;
pub mod ordering;
pub(crate) mod pcg;
pub(crate) mod pmultigrid;
pub(crate) mod precond;
pub mod preload;
pub mod quadrature;
pub mod sparse;
