//! `facesim render`: a mesh to a PNG picture (orthographic, z-buffered, Lambert-shaded,
//! vertex colours when the mesh has them), so results can be looked at and put in reports
//! without a viewer.

use facesim::error::{Error, Result};
use facesim::mesh::Mesh;
use facesim::output::write_bytes_atomic;
use facesim::vec3::{cross, dot, norm, sub};
use std::path::Path;

/// Views in LPS: the patient's front (camera at −y), left side (camera at +x), top (+z).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum View {
    Front,
    Left,
    Right,
    Top,
}

impl View {
    /// (right, up, towards the camera) unit vectors.
    fn axes(self) -> ([f64; 3], [f64; 3], [f64; 3]) {
        match self {
            // Facing the patient: the patient's left (+x) appears on the image's right.
            View::Front => ([1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]),
            View::Left => ([0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]),
            View::Right => ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]),
            View::Top => ([1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]),
        }
    }
}

/// Render into RGB pixels (row-major, top row first).
pub fn render(meshes: &[&Mesh], view: View, size: usize) -> Vec<u8> {
    let cam = Camera::fit(meshes, view, size);
    let light = cam.light();
    let mut canvas = Canvas::new(size);
    for m in meshes {
        for tri in &m.triangles {
            let p = tri.map(|i| m.vertices[i as usize]);
            let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
            let ln = norm(n);
            if ln == 0.0 {
                continue;
            }
            // Two-sided lighting: open surfaces are seen from both sides.
            let shade = 0.25 + 0.75 * (dot(n, light) / ln).abs();
            let col = triangle_colour(m, tri);
            canvas.fill(p.map(|v| cam.project(v)), col, shade);
        }
    }
    canvas.img
}

/// Orthographic camera of a view, framing the meshes' extent with a 5 % margin.
struct Camera {
    /// (right, up, towards the camera) unit vectors.
    r: [f64; 3],
    u: [f64; 3],
    c: [f64; 3],
    centre: [f64; 2],
    span: f64,
    size: usize,
}

impl Camera {
    fn fit(meshes: &[&Mesh], view: View, size: usize) -> Camera {
        let (r, u, c) = view.axes();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for m in meshes {
            for v in &m.vertices {
                let p = [dot(*v, r), dot(*v, u)];
                for a in 0..2 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
            }
        }
        let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-9) * 1.05;
        let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
        Camera {
            r,
            u,
            c,
            centre,
            span,
            size,
        }
    }

    /// Pixel coordinates (x right, y down) and depth towards the camera.
    fn project(&self, v: [f64; 3]) -> (f64, f64, f64) {
        let x = (dot(v, self.r) - self.centre[0]) / self.span + 0.5;
        let y = 0.5 - (dot(v, self.u) - self.centre[1]) / self.span;
        (x * self.size as f64, y * self.size as f64, dot(v, self.c))
    }

    /// Unit light direction: from the camera, a little above and to the left, so faces square
    /// to the view are not all equally bright.
    fn light(&self) -> [f64; 3] {
        let (r, u, c) = (self.r, self.u, self.c);
        let l = [
            c[0] + 0.3 * u[0] - 0.3 * r[0],
            c[1] + 0.3 * u[1] - 0.3 * r[1],
            c[2] + 0.3 * u[2] - 0.3 * r[2],
        ];
        let n = norm(l);
        l.map(|x| x / n)
    }
}

/// A triangle's colour: the mean of its vertex colours, skin tone when the mesh has none.
fn triangle_colour(m: &Mesh, tri: &[u32; 3]) -> [f64; 3] {
    match &m.colors {
        Some(cs) => {
            let mut a = [0.0; 3];
            for &i in tri {
                for k in 0..3 {
                    a[k] += cs[i as usize][k] as f64 / 3.0;
                }
            }
            a
        }
        None => [225.0, 190.0, 160.0],
    }
}

/// RGB pixels with a depth buffer (larger depth is nearer the camera).
struct Canvas {
    size: usize,
    img: Vec<u8>,
    depth: Vec<f64>,
}

impl Canvas {
    fn new(size: usize) -> Canvas {
        Canvas {
            size,
            img: vec![255u8; size * size * 3],
            depth: vec![f64::NEG_INFINITY; size * size],
        }
    }

    /// Fill the pixels whose centres lie in the projected triangle `q` and that it is nearest
    /// at, with `col` scaled by `shade`.
    fn fill(&mut self, q: [(f64, f64, f64); 3], col: [f64; 3], shade: f64) {
        let size = self.size;
        let Some((xmin, xmax, ymin, ymax)) = pixel_box(q, size) else {
            return;
        };
        let area = (q[1].0 - q[0].0) * (q[2].1 - q[0].1) - (q[2].0 - q[0].0) * (q[1].1 - q[0].1);
        if area.abs() < 1e-12 {
            return;
        }
        for y in ymin..=ymax {
            for x in xmin..=xmax {
                let (fx, fy) = (x as f64 + 0.5, y as f64 + 0.5);
                let w0 = ((q[1].0 - fx) * (q[2].1 - fy) - (q[2].0 - fx) * (q[1].1 - fy)) / area;
                let w1 = ((q[2].0 - fx) * (q[0].1 - fy) - (q[0].0 - fx) * (q[2].1 - fy)) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let z = w0 * q[0].2 + w1 * q[1].2 + w2 * q[2].2;
                let k = y * size + x;
                if z > self.depth[k] {
                    self.depth[k] = z;
                    for (ch, v) in col.iter().enumerate() {
                        self.img[3 * k + ch] = (v * shade).clamp(0.0, 255.0) as u8;
                    }
                }
            }
        }
    }
}

/// Pixel range (xmin, xmax, ymin, ymax) covering the projected triangle `q`, clipped to the
/// image; None when it lies wholly left of or above the image.
fn pixel_box(q: [(f64, f64, f64); 3], size: usize) -> Option<(usize, usize, usize, usize)> {
    let xmin = q
        .iter()
        .map(|v| v.0)
        .fold(f64::INFINITY, f64::min)
        .floor()
        .max(0.0) as usize;
    let xmax = q
        .iter()
        .map(|v| v.0)
        .fold(f64::NEG_INFINITY, f64::max)
        .ceil()
        .min(size as f64 - 1.0);
    let ymin = q
        .iter()
        .map(|v| v.1)
        .fold(f64::INFINITY, f64::min)
        .floor()
        .max(0.0) as usize;
    let ymax = q
        .iter()
        .map(|v| v.1)
        .fold(f64::NEG_INFINITY, f64::max)
        .ceil()
        .min(size as f64 - 1.0);
    if xmax < 0.0 || ymax < 0.0 {
        return None;
    }
    Some((xmin, xmax as usize, ymin, ymax as usize))
}

pub fn write_png(rgb: &[u8], size: usize, dest: &Path) -> Result<()> {
    write_bytes_atomic(dest, |w| {
        let mut enc = png::Encoder::new(w, size as u32, size as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().map_err(std::io::Error::other)?;
        writer
            .write_image_data(rgb)
            .map_err(std::io::Error::other)?;
        writer.finish().map_err(std::io::Error::other)
    })
    .map_err(|e| Error::output(dest, e))
}
