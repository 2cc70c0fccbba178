//! The charts facesim writes beside its tables: sweep.svg (`facesim sweep`, the Python
//! package's `sweep(out=…)`), validation.svg (`facesim validate`) and the lab's study charts
//! share one font and palette. The product library draws nothing; this crate carries the chart
//! dependency for the programs that do.

pub mod sweep;
pub mod validation;
