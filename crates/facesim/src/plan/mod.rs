//! Re-planning without re-solving (docs/design/plan-basis.md).
//!
//! A segment's rigid move x ↦ R x + t′ (t′ = (I − R)·pivot + translate) displaces its bone by
//! M·[x; 1] with M = [R − I | t′], linear in M's 12 entries. In a linear model whose moved bone
//! follows M exactly, the face displacement is Σ_s Σ_k m_{s,k} B_{s,k}: the [`PlanBasis`], 12
//! face displacement fields per segment, solved once with the run's factor.
//!
//! - [`basis`]: the basis, its matrices and the prediction of any plan from it;
//! - [`c1`]: the C1 models' basis, their linearisation at the pre-operative state;
//! - [`mod@file`]: `plan_basis.bin`, the basis stored with a run's outputs.
//!
//! The commands that use a stored basis, `facesim replan` and `facesim sweep`, are
//! `crate::commands`; this module is the maths and the file only (it imports neither the
//! pipeline nor the report).

pub mod basis;
pub mod c1;
pub mod file;

pub use basis::{PlanBasis, SegmentBasis, matrix};
