//! Landmark registration of a face scan to the CT: least-squares rigid or similarity transform
//! (Umeyama 1991, closed form by SVD of the cross-covariance), x_ct ≈ s R x_scan + t.

use crate::error::{Error, NumericalKind, Result};
use nalgebra::{Matrix3, Vector3};

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Transform {
    pub rotation: [[f64; 3]; 3],
    pub translation: [f64; 3],
    pub scale: f64,
    /// RMS landmark residual after the fit (mm).
    pub rms_residual: f64,
    pub max_residual: f64,
}

impl Transform {
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let mut q = self.translation;
        for (r, qr) in q.iter_mut().enumerate() {
            *qr += self.scale * (0..3).map(|c| self.rotation[r][c] * p[c]).sum::<f64>();
        }
        q
    }
}

pub fn fit(scan: &[[f64; 3]], ct: &[[f64; 3]], allow_scale: bool) -> Result<Transform> {
    let n = scan.len();
    if n < 3 || n != ct.len() {
        return Err(Error::config(format!(
            "[registration] needs >= 3 landmark pairs, got {n}"
        )));
    }
    let v = |p: &[f64; 3]| Vector3::new(p[0], p[1], p[2]);
    let ms = scan.iter().map(v).sum::<Vector3<f64>>() / n as f64;
    let mc = ct.iter().map(v).sum::<Vector3<f64>>() / n as f64;
    let mut cov = Matrix3::zeros();
    let mut var_s = 0.0;
    for (a, b) in scan.iter().zip(ct) {
        let (ds, dc) = (v(a) - ms, v(b) - mc);
        cov += dc * ds.transpose();
        var_s += ds.norm_squared();
    }
    cov /= n as f64;
    var_s /= n as f64;
    let svd = cov.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Err(Error::numerical(
            NumericalKind::Singular,
            "registration SVD failed",
        ));
    };
    let mut d = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    // Collinear landmarks leave the rotation about their line undetermined.
    let sv = svd.singular_values;
    if sv[1] <= 1e-9 * sv[0].max(1e-300) {
        return Err(Error::config(
            "[registration] landmarks are collinear: the rotation is undetermined",
        ));
    }
    let r = u * d * vt;
    let s = if allow_scale {
        (sv.component_mul(&d.diagonal())).sum() / var_s
    } else {
        1.0
    };
    let t = mc - s * r * ms;
    let mut tr = Transform {
        rotation: [0, 1, 2].map(|i| [0, 1, 2].map(|j| r[(i, j)])),
        translation: [t[0], t[1], t[2]],
        scale: s,
        rms_residual: 0.0,
        max_residual: 0.0,
    };
    let res: Vec<f64> = scan
        .iter()
        .zip(ct)
        .map(|(a, b)| {
            let q = tr.apply(*a);
            ((q[0] - b[0]).powi(2) + (q[1] - b[1]).powi(2) + (q[2] - b[2]).powi(2)).sqrt()
        })
        .collect();
    tr.rms_residual = (res.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
    tr.max_residual = res.iter().cloned().fold(0.0, f64::max);
    Ok(tr)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_known_similarity_exactly() {
        let (c, s) = (0.8f64, 0.6f64);
        let truth = Transform {
            rotation: [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
            translation: [3.0, -7.0, 12.5],
            scale: 1.1,
            rms_residual: 0.0,
            max_residual: 0.0,
        };
        let scan = [
            [0.0, 0.0, 0.0],
            [50.0, 0.0, 10.0],
            [0.0, 40.0, -5.0],
            [20.0, 30.0, 60.0],
        ];
        let ct: Vec<[f64; 3]> = scan.iter().map(|p| truth.apply(*p)).collect();
        let f = fit(&scan, &ct, true).unwrap();
        assert!((f.scale - 1.1).abs() < 1e-12);
        assert!(f.rms_residual < 1e-10);
        let rigid = fit(&scan, &ct, false).unwrap();
        assert_eq!(rigid.scale, 1.0);
        assert!(
            rigid.rms_residual > 1.0,
            "a rigid fit cannot absorb a 10% scale"
        );
        assert!(
            fit(
                &[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
                &[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
                false
            )
            .is_err()
        );
    }
}
