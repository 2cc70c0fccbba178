//! What a hyperelastic material gives the nonlinear solves: its strain energy density, first
//! Piola–Kirchhoff stress and consistent tangent (`nonlinear::NeoHooke`, CalculiX's form;
//! `stable_neo_hooke::StableNeoHooke`, the product's).

use nalgebra::Matrix3;

/// ∂P_iJ/∂F_kL, indexed [3i + J][3k + L].
pub type Tangent = [[f64; 9]; 9];

/// A hyperelastic material: its strain energy density W(F), first Piola–Kirchhoff stress and
/// consistent tangent; None where it is undefined (J ≤ 0 for the classical forms).
pub trait Hyperelastic {
    fn energy(&self, f: &Matrix3<f64>) -> Option<f64>;
    fn stress(&self, f: &Matrix3<f64>) -> Option<Matrix3<f64>>;
    fn stress_tangent(&self, f: &Matrix3<f64>) -> Option<(Matrix3<f64>, Tangent)>;
}
