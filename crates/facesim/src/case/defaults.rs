//! The Rust defaults of every case.toml key, equal to pipeline/defaults.toml (tested below): a
//! caller builds a case in memory with `Case { ct: CtSection::new(path), ..Case::default() }`
//! and no case.toml.

use super::schema::*;

/// The documented defaults, compiled in so the binary works from any directory.
pub const DEFAULTS_TOML: &str = include_str!("../../../../pipeline/defaults.toml");

// `Case::default()` is derived: every section's default below, no lists, no optional parts.

impl Default for Tissue {
    fn default() -> Tissue {
        Tissue {
            method: TissueMethod::Windows,
            head_threshold: -500.0,
            skin_thickness_mm: 2.0,
            min_bone_component_mm3: 500.0,
            fat_dark: -190.0,
            fat_bright: -100.0,
            soft: -30.0,
            bone: 300.0,
            stiffness: Stiffness {
                skin: 200.0,
                muscle: 100.0,
                fat_dark: 10.0,
                fat_bright: 20.0,
            },
        }
    }
}

impl Default for Extract {
    fn default() -> Extract {
        Extract {
            method: ExtractMethod::Rangescan,
            angle_step_deg: 2.0,
            z_step_mm: 0.0,
            smooth_iterations: 0,
            decimate_target: 0,
            decimate_max_error_mm: 0.5,
        }
    }
}

impl Default for Springs {
    fn default() -> Springs {
        Springs {
            max_length_mm: 40.0,
            struts: true,
        }
    }
}

impl Default for Surface {
    fn default() -> Surface {
        Surface {
            alpha: 0.01,
            beta: 0.02,
            parameterization: Parameterization::Cylindrical,
            movable: None,
            regions: Vec::new(),
        }
    }
}

impl Default for Solve {
    fn default() -> Solve {
        Solve {
            model: SolveModel::Tet,
            steps: 4,
            k_c: 2.5e-6,
            koch_k_c: 1e-8,
            restrict: true,
            coarse_triangles: 0,
            shell_mm: 3.0,
            shell_poisson: 0.45,
        }
    }
}

impl Default for Tet {
    fn default() -> Tet {
        let e = |youngs_kpa, poisson| TissueElastic {
            youngs_kpa,
            poisson,
        };
        Tet {
            material: TetMaterial::Linear,
            element: TetElement::Linear,
            load_steps: 4,
            sliding: true,
            mucosa_gap_mm: 3.0,
            cut_release_mm: 8.0,
            release_cuts: true,
            tear_gap: true,
            accept_inverted: false,
            error_estimate: true,
            skin_size_mm: 4.0,
            deep_size_mm: 8.0,
            margin_mm: 30.0,
            degloved_maxilla: Degloved::Auto,
            degloved_chin: Degloved::Auto,
            scan_end: ScanEndHold::Slides,
            skin: e(30.0, 0.45),
            muscle: e(10.0, 0.45),
            fat_dark: e(2.0, 0.45),
            fat_bright: e(3.0, 0.45),
            retired_nose_youngs_kpa: serde::de::IgnoredAny,
            retired_nose_base_above_sn_mm: serde::de::IgnoredAny,
            retired_septum_detached: serde::de::IgnoredAny,
        }
    }
}

impl Default for Output {
    fn default() -> Output {
        Output { subdivide: 2 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    const MIN: &str = "[ct]\npath = \"ct.nii.gz\"\n";

    #[test]
    fn rust_defaults_equal_defaults_toml() {
        let parsed = Case::parse(MIN, Path::new("case.toml")).unwrap();
        let built = Case {
            ct: CtSection::new("ct.nii.gz"),
            ..Case::default()
        };
        let json = |c: &Case| serde_json::to_value(c).unwrap();
        assert_eq!(json(&built), json(&parsed));
        built.validate(Path::new("in memory")).unwrap();
    }
}
