//! facesim — predicting a patient's face after cranio-maxillofacial surgery, after
//! Koch, Gross et al. 1996 ("Simulating Facial Surgery Using Finite Element Models").
//!
//! The modules follow the pipeline's stages:
//! `volume` (read CT) → `segment` (tissues) → `surface` (skin and skull meshes) → … → `run`.

pub mod error;
pub mod mesh;
pub mod output;
pub mod volume;

pub use error::{Error, Result};
