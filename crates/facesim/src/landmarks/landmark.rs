//! A landmark and what is said of it: its kind and source, its position or why it is missing,
//! its anchor on the face, its place before and after, and the ordered maps report.json keeps
//! them in. Every other module of `landmarks/` builds or reads these types.

use crate::compare::{SurfaceIndex, barycentric};
use crate::mesh::Mesh;
use crate::vec3::sub;
use serde::de::{Deserializer, MapAccess, Visitor};
use serde::ser::{SerializeMap, Serializer};
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    Soft,
    Bone,
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Source {
    Detected,
    User,
}

/// One landmark on the pre-operative anatomy (LPS mm), or why it is missing.
#[derive(Clone, Debug, Serialize)]
pub struct Landmark {
    pub label: String,
    pub kind: Kind,
    pub position: Option<[f64; 3]>,
    pub source: Source,
    pub missing: Option<String>,
}

impl Landmark {
    pub fn missing(label: &str, kind: Kind, why: String) -> Landmark {
        Landmark {
            label: label.into(),
            kind,
            position: None,
            source: Source::Detected,
            missing: Some(why),
        }
    }
}

/// A landmark before and after.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Carried {
    pub label: String,
    pub kind: Kind,
    pub source: Source,
    pub pre: Option<[f64; 3]>,
    pub post: Option<[f64; 3]>,
    pub change_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub missing: Option<String>,
}

/// Where a soft-tissue landmark sits on the face: a triangle of `face_pre`, barycentric weights
/// of its closest point there, and the landmark's offset from that point (0 for a detected
/// one). The same material point on any face with face_pre's triangles is
/// Σ wᵢ·vᵢ + offset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceAnchor {
    pub triangle: u32,
    pub weights: [f64; 3],
    pub offset: [f64; 3],
}

impl SurfaceAnchor {
    /// The anchor of `p` on `face` (`index` built on `face`).
    pub fn new(index: &SurfaceIndex, face: &Mesh, p: [f64; 3]) -> SurfaceAnchor {
        let (_, q, t) = index.closest_triangle(p);
        let [a, b, c] = face.triangles[t].map(|i| face.vertices[i as usize]);
        SurfaceAnchor {
            triangle: t as u32,
            weights: barycentric(q, a, b, c),
            offset: sub(p, q),
        }
    }

    /// The anchored point on vertices with face_pre's order.
    pub fn place(&self, triangles: &[[u32; 3]], vertices: &[[f64; 3]]) -> [f64; 3] {
        let [a, b, c] = triangles[self.triangle as usize].map(|i| vertices[i as usize]);
        let w = self.weights;
        [0, 1, 2].map(|k| w[0] * a[k] + w[1] * b[k] + w[2] * c[k] + self.offset[k])
    }
}

/// A map that keeps its insertion order in JSON (report.json's `landmarks`, `measurements`,
/// `regions`).
#[derive(Clone, Debug)]
pub struct Ordered<T>(pub Vec<(String, T)>);

impl<T> Default for Ordered<T> {
    fn default() -> Self {
        Ordered(Vec::new())
    }
}

impl<T: Serialize> Serialize for Ordered<T> {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in &self.0 {
            m.serialize_entry(k, v)?;
        }
        m.end()
    }
}

/// Read in the file's order (a map's keys once each, as written).
impl<'de, T: Deserialize<'de>> Deserialize<'de> for Ordered<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for V<T> {
            type Value = Ordered<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a map")
            }
            fn visit_map<A: MapAccess<'de>>(
                self,
                mut a: A,
            ) -> std::result::Result<Self::Value, A::Error> {
                let mut v = Vec::with_capacity(a.size_hint().unwrap_or(0));
                while let Some(e) = a.next_entry()? {
                    v.push(e);
                }
                Ok(Ordered(v))
            }
        }
        d.deserialize_map(V(std::marker::PhantomData))
    }
}

/// (label, position) of the landmarks that have one.
pub fn positions(lms: &[Landmark]) -> Vec<(String, [f64; 3])> {
    lms.iter()
        .filter_map(|l| l.position.map(|p| (l.label.clone(), p)))
        .collect()
}
