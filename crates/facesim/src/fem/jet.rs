//! Second-order forward automatic differentiation in two variables: exact first and second
//! derivatives of the (rational) shape functions, instead of the paper's finite differences.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// f and its derivatives with respect to two variables (x, y).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Jet {
    pub v: f64,
    pub x: f64,
    pub y: f64,
    pub xx: f64,
    pub xy: f64,
    pub yy: f64,
}

impl Jet {
    pub const fn constant(v: f64) -> Jet {
        Jet {
            v,
            x: 0.0,
            y: 0.0,
            xx: 0.0,
            xy: 0.0,
            yy: 0.0,
        }
    }
    /// The independent variables at (x0, y0).
    pub(crate) fn vars(x0: f64, y0: f64) -> (Jet, Jet) {
        (
            Jet {
                v: x0,
                x: 1.0,
                ..Jet::constant(0.0)
            },
            Jet {
                v: y0,
                y: 1.0,
                ..Jet::constant(0.0)
            },
        )
    }
    pub fn scale(self, k: f64) -> Jet {
        Jet {
            v: k * self.v,
            x: k * self.x,
            y: k * self.y,
            xx: k * self.xx,
            xy: k * self.xy,
            yy: k * self.yy,
        }
    }
    pub(crate) fn recip(self) -> Jet {
        let g = self.v;
        let g2 = g * g;
        let g3 = g2 * g;
        Jet {
            v: 1.0 / g,
            x: -self.x / g2,
            y: -self.y / g2,
            xx: 2.0 * self.x * self.x / g3 - self.xx / g2,
            xy: 2.0 * self.x * self.y / g3 - self.xy / g2,
            yy: 2.0 * self.y * self.y / g3 - self.yy / g2,
        }
    }
}

impl Add for Jet {
    type Output = Jet;
    fn add(self, o: Jet) -> Jet {
        Jet {
            v: self.v + o.v,
            x: self.x + o.x,
            y: self.y + o.y,
            xx: self.xx + o.xx,
            xy: self.xy + o.xy,
            yy: self.yy + o.yy,
        }
    }
}
impl Sub for Jet {
    type Output = Jet;
    fn sub(self, o: Jet) -> Jet {
        self + (-o)
    }
}
impl Neg for Jet {
    type Output = Jet;
    fn neg(self) -> Jet {
        self.scale(-1.0)
    }
}
impl Mul for Jet {
    type Output = Jet;
    fn mul(self, o: Jet) -> Jet {
        Jet {
            v: self.v * o.v,
            x: self.x * o.v + self.v * o.x,
            y: self.y * o.v + self.v * o.y,
            xx: self.xx * o.v + 2.0 * self.x * o.x + self.v * o.xx,
            xy: self.xy * o.v + self.x * o.y + self.y * o.x + self.v * o.xy,
            yy: self.yy * o.v + 2.0 * self.y * o.y + self.v * o.yy,
        }
    }
}
impl Div for Jet {
    type Output = Jet;
    #[allow(clippy::suspicious_arithmetic_impl)] // f / g = f · (1/g), with 1/g's own jet
    fn div(self, o: Jet) -> Jet {
        self * o.recip()
    }
}
impl Add<f64> for Jet {
    type Output = Jet;
    fn add(self, k: f64) -> Jet {
        Jet {
            v: self.v + k,
            ..self
        }
    }
}
impl Mul<f64> for Jet {
    type Output = Jet;
    fn mul(self, k: f64) -> Jet {
        self.scale(k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rational_function_derivatives_match_hand_calculus() {
        // f = x² y / (1 + x y) at (0.3, 0.7).
        let (x, y) = Jet::vars(0.3, 0.7);
        let f = x * x * y / (x * y + 1.0);
        let (a, b) = (0.3f64, 0.7f64);
        let d = 1.0 + a * b;
        let fx = (2.0 * a * b * d - a * a * b * b) / (d * d);
        let fy = (a * a * d - a * a * b * a) / (d * d);
        assert!((f.v - a * a * b / d).abs() < 1e-15);
        assert!((f.x - fx).abs() < 1e-14 && (f.y - fy).abs() < 1e-14);
        // Second derivatives against central differences of the exact first derivatives.
        let h = 1e-6;
        let g = |a: f64, b: f64| {
            let (x, y) = Jet::vars(a, b);
            x * x * y / (x * y + 1.0)
        };
        let fxx = (g(a + h, b).x - g(a - h, b).x) / (2.0 * h);
        let fxy = (g(a, b + h).x - g(a, b - h).x) / (2.0 * h);
        let fyy = (g(a, b + h).y - g(a, b - h).y) / (2.0 * h);
        assert!(
            (f.xx - fxx).abs() < 1e-8 && (f.xy - fxy).abs() < 1e-8 && (f.yy - fyy).abs() < 1e-8
        );
    }
}
