//! A face predicted by one model, with what that model built (`S`): each model returns its own
//! `Predicted<…>`, and `crate::model` wraps them into the one [`super::Prediction`].

use crate::mesh::Mesh;
use crate::plan::PlanBasis;

pub struct Predicted<S> {
    /// The skin of face_pre: the full skin (the scan as given, or the extracted skin).
    pub skin: Mesh,
    /// The predicted face, same vertices in the same order as `skin`, without colours.
    pub face_post: Mesh,
    /// The plan basis (docs/design/plan-basis.md), when the model built one.
    pub basis: Option<PlanBasis>,
    /// What the model built and solved.
    pub solved: S,
}

impl<S> Predicted<S> {
    /// The same prediction with what the model built turned by `f`.
    pub fn map<T>(self, f: impl FnOnce(S) -> T) -> Predicted<T> {
        Predicted {
            skin: self.skin,
            face_post: self.face_post,
            basis: self.basis,
            solved: f(self.solved),
        }
    }
}
