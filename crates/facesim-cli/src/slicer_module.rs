//! `FaceSimPredict`: facesim as a 3D Slicer CLI module (docs/guide/slicer.md).
//!
//! `FaceSimPredict --xml` prints the module's Slicer Execution Model description; called with
//! the flags it declares (as Slicer calls it: volumes as temporary .nrrd files, models as .vtk,
//! transforms as .tfm), it writes a temporary case directory, runs the pipeline and writes the
//! outputs where the flags say, reporting progress on stdout with `<filter-progress>` lines.

use facesim::error::{Error, Result};
use facesim::mesh;
use facesim::observe::Observer;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

const NAME: &str = "FaceSimPredict";

fn xml() -> String {
    format!(
        r#"<?xml version="1.0" encoding="utf-8"?>
<executable>
  <category>Surgery</category>
  <title>FaceSim Predict</title>
  <description><![CDATA[Predicts the patient's face after jaw surgery (e.g. a maxillary or mandibular advancement) from a CT: the soft tissue is modelled between skin and bone, the bone segments are moved as planned, and the predicted face is written as a model with the displacement (mm, LPS) as point data.]]></description>
  <version>{version}</version>
  <documentation-url>https://github.com/facesim/facesim/blob/main/docs/guide/slicer.md</documentation-url>
  <license>See the facesim repository</license>
  <contributor>The facesim project</contributor>
  <acknowledgements><![CDATA[After Koch, Gross et al., Simulating Facial Surgery Using Finite Element Models (SIGGRAPH 1996).]]></acknowledgements>
  <parameters>
    <label>Inputs</label>
    <description><![CDATA[The CT, the bone segments and how they move.]]></description>
    <image>
      <name>ct</name>
      <label>CT volume</label>
      <channel>input</channel>
      <longflag>ct</longflag>
      <description><![CDATA[The pre-operative CT (HU).]]></description>
    </image>
    <geometry fileExtensions=".vtk">
      <name>face</name>
      <label>Face model (optional)</label>
      <channel>input</channel>
      <longflag>face</longflag>
      <description><![CDATA[A surface scan of the face in the CT's frame; without it the skin is extracted from the CT.]]></description>
    </geometry>
    <geometry multiple="true" fileExtensions=".vtk">
      <name>segments</name>
      <label>Bone segment models</label>
      <channel>input</channel>
      <longflag>segments</longflag>
      <description><![CDATA[Closed surfaces of the bone segments that move (e.g. segments exported as models): the bone inside each moves.]]></description>
    </geometry>
    <transform multiple="true" fileExtensions=".tfm">
      <name>transforms</name>
      <label>Segment transforms</label>
      <channel>input</channel>
      <longflag>transforms</longflag>
      <description><![CDATA[One linear (rigid) transform per bone segment, in the same order: the move applied to the segment in the Transforms module.]]></description>
    </transform>
    <string multiple="true">
      <name>surgery</name>
      <label>Surgery (clinical terms)</label>
      <longflag>surgery</longflag>
      <description><![CDATA[Instead of segment models: one entry per osteotomy as a surgeon states it, "KIND key=value ...", e.g. "le-fort-i advance_mm=5 up_mm=2" or "bsso advance_mm=-4"; KIND is le-fort-i, bsso or genioplasty; keys advance_mm, up_mm, left_mm, pitch_deg, roll_deg, yaw_deg, pivot, autorotate, name (docs/guide/planning.md). The cuts are found from the CT.]]></description>
    </string>
    <geometry fileExtensions=".vtk">
      <name>movable</name>
      <label>Movable region model (optional)</label>
      <channel>input</channel>
      <longflag>movable</longflag>
      <description><![CDATA[A closed surface around the part of the face that may move; the rest of the skin is held. Without it all skin may move.]]></description>
    </geometry>
    <string-enumeration>
      <name>model</name>
      <label>Soft-tissue model</label>
      <longflag>model</longflag>
      <description><![CDATA[tet: volumetric soft tissue; equilibrium: C1 skin surface on tissue springs.]]></description>
      <default>tet</default>
      <element>tet</element>
      <element>equilibrium</element>
    </string-enumeration>
  </parameters>
  <parameters>
    <label>Outputs</label>
    <description><![CDATA[The predicted face and its landmarks.]]></description>
    <geometry fileExtensions=".vtp">
      <name>predictedFace</name>
      <label>Predicted face</label>
      <channel>output</channel>
      <longflag>predictedFace</longflag>
      <description><![CDATA[The predicted face, with point data displacement_mm (3 components, LPS) and displacement_magnitude_mm.]]></description>
    </geometry>
    <pointfile fileExtensions=".mrk.json" coordinateSystem="lps">
      <name>landmarks</name>
      <label>Predicted landmarks</label>
      <channel>output</channel>
      <longflag>landmarks</longflag>
      <description><![CDATA[Soft-tissue and bony landmarks on the predicted face, when facesim finds them.]]></description>
    </pointfile>
  </parameters>
</executable>
"#,
        version = env!("CARGO_PKG_VERSION")
    )
}

/// The flags of one call (values as Slicer passes them; `multiple` flags repeat or hold a
/// comma-separated list).
#[derive(Default, Debug)]
struct Args {
    ct: Option<PathBuf>,
    face: Option<PathBuf>,
    segments: Vec<PathBuf>,
    transforms: Vec<PathBuf>,
    movable: Option<PathBuf>,
    /// `--surgery` entries, "KIND key=value ...".
    surgery: Vec<String>,
    model: Option<String>,
    predicted_face: Option<PathBuf>,
    landmarks: Option<PathBuf>,
}

fn parse_args(argv: &[String]) -> std::result::Result<Args, String> {
    let mut a = Args::default();
    let mut i = 0;
    while i < argv.len() {
        let (flag, inline) = match argv[i].split_once('=') {
            Some((f, v)) if f.starts_with("--") => (f.to_string(), Some(v.to_string())),
            _ => (argv[i].clone(), None),
        };
        let value = match inline {
            Some(v) => v,
            None => {
                i += 1;
                argv.get(i)
                    .cloned()
                    .ok_or_else(|| format!("{flag} needs a value"))?
            }
        };
        let list = |v: &str| -> Vec<PathBuf> {
            v.split(',')
                .filter(|s| !s.is_empty())
                .map(PathBuf::from)
                .collect()
        };
        match flag.as_str() {
            "--ct" => a.ct = Some(value.into()),
            "--face" => a.face = Some(value.into()),
            "--segments" => a.segments.extend(list(&value)),
            "--transforms" => a.transforms.extend(list(&value)),
            "--movable" => a.movable = Some(value.into()),
            "--surgery" => a.surgery.extend(
                value
                    .split(',')
                    .map(str::trim)
                    .filter(|s| !s.is_empty())
                    .map(String::from),
            ),
            "--model" => a.model = Some(value),
            "--predictedFace" => a.predicted_face = Some(value.into()),
            "--landmarks" => a.landmarks = Some(value.into()),
            other => return Err(format!("unknown flag {other} (see FaceSimPredict --xml)")),
        }
        i += 1;
    }
    Ok(a)
}

/// Slicer's progress protocol on stdout: a fraction per stage started.
struct FilterProgress {
    started: AtomicUsize,
}

impl Observer for FilterProgress {
    fn started(&self, what: &str) {
        // About 14 stages in a run; the last 5 % is the module's own output writing.
        let n = self.started.fetch_add(1, Ordering::Relaxed) + 1;
        let f = (n as f64 / 15.0).min(0.95);
        let mut out = std::io::stdout().lock();
        let _ = writeln!(
            out,
            "<filter-progress>{f:.3}</filter-progress>\n<filter-comment>{what}</filter-comment>"
        );
        let _ = out.flush();
    }
}

fn toml_path(p: &Path) -> String {
    // TOML basic string: escape backslashes and quotes.
    p.display()
        .to_string()
        .replace('\\', "\\\\")
        .replace('"', "\\\"")
}

fn absolute(p: &Path) -> PathBuf {
    std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf())
}

/// The case.toml for these flags; models Slicer hands over are converted to what a case reads
/// (the face to PLY) inside `dir`.
fn write_case(a: &Args, dir: &Path) -> Result<()> {
    let ct =
        a.ct.as_ref()
            .ok_or_else(|| Error::config("FaceSimPredict: --ct (the CT volume) is required"))?;
    if a.segments.len() != a.transforms.len() {
        return Err(Error::config(format!(
            "FaceSimPredict: {} bone segment models but {} transforms: give one transform per segment, in the same order",
            a.segments.len(),
            a.transforms.len()
        )));
    }
    let mut t = format!(
        "name = \"{NAME}\"\n\n[ct]\npath = \"{}\"\n",
        toml_path(&absolute(ct))
    );
    if let Some(face) = &a.face {
        let m = mesh::model_file::read_model(face)?;
        m.check(face)?;
        let ply = dir.join("face.ply");
        mesh::ply::write(&m, &ply, mesh::ply::Encoding::BinaryLittleEndian)?;
        t.push_str("\n[skin]\npath = \"face.ply\"\n");
    }
    if let Some(model) = &a.model {
        if model != "tet" && model != "equilibrium" {
            return Err(Error::config(format!(
                "FaceSimPredict: --model {model}: expected tet or equilibrium"
            )));
        }
        t.push_str(&format!("\n[solve]\nmodel = \"{model}\"\n"));
    }
    if let Some(m) = &a.movable {
        t.push_str(&format!(
            "\n[surface]\nmovable = {{ surface = \"{}\" }}\n",
            toml_path(&absolute(m))
        ));
    }
    for (i, (s, tr)) in a.segments.iter().zip(&a.transforms).enumerate() {
        let name = s
            .file_stem()
            .map(|n| n.to_string_lossy().replace('"', ""))
            .unwrap_or_else(|| format!("segment{}", i + 1));
        t.push_str(&format!(
            "\n[[osteotomy]]\nname = \"{}-{}\"\nregion = {{ surface = \"{}\" }}\ntransform = \"{}\"\n",
            i + 1,
            name,
            toml_path(&absolute(s)),
            toml_path(&absolute(tr))
        ));
    }
    for entry in &a.surgery {
        t.push_str(&surgery_table(entry)?);
    }
    let case = dir.join("case.toml");
    std::fs::write(&case, t).map_err(|e| Error::output(&case, e))
}

/// One `--surgery` entry ("KIND key=value ...") as a `[[surgery]]` table; numbers and booleans
/// stay bare, anything else (a pivot's name) is quoted. The case's own checks judge the keys.
fn surgery_table(entry: &str) -> Result<String> {
    let mut words = entry.split_whitespace();
    let kind = words.next().unwrap_or_default();
    let mut t = format!("\n[[surgery]]\nkind = \"{}\"\n", kind.replace('"', ""));
    for w in words {
        let Some((k, v)) = w.split_once('=') else {
            return Err(Error::config(format!(
                "FaceSimPredict: --surgery \"{entry}\": \"{w}\" is not key=value (e.g. advance_mm=5)"
            )));
        };
        let bare = v.parse::<f64>().is_ok() || v == "true" || v == "false";
        let value = if bare {
            v.to_string()
        } else {
            format!("\"{}\"", v.replace('"', ""))
        };
        t.push_str(&format!("{} = {value}\n", k.replace(['"', '=', ' '], "")));
    }
    Ok(t)
}

/// The predicted face in the format its file name asks for (.vtp, .vtk, .stl, .ply, .obj).
fn write_face(o: &facesim::commands::Outcome, dest: &Path) -> Result<()> {
    let disp: Vec<f64> = o
        .skin
        .vertices
        .iter()
        .zip(&o.face_post.vertices)
        .flat_map(|(a, b)| facesim::vec3::sub(*b, *a))
        .collect();
    let mag: Vec<f64> = disp
        .chunks(3)
        .map(|d| facesim::vec3::norm([d[0], d[1], d[2]]))
        .collect();
    let arrays = [
        mesh::vtk::PointArray {
            name: "displacement_mm".into(),
            components: 3,
            values: disp,
        },
        mesh::vtk::PointArray {
            name: "displacement_magnitude_mm".into(),
            components: 1,
            values: mag,
        },
    ];
    let ext = dest
        .extension()
        .map(|e| e.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "vtp" => mesh::vtp::write_vtp(&o.face_post, &arrays, dest),
        "vtk" => mesh::vtk::write_legacy(&o.face_post, &arrays, dest),
        "stl" => mesh::stl::write(&o.face_post, dest, "facesim SPACE=LPS"),
        _ => mesh::write_mesh(&o.face_post, dest),
    }
}

fn run(a: &Args) -> Result<()> {
    let dest = a.predicted_face.as_ref().ok_or_else(|| {
        Error::config("FaceSimPredict: --predictedFace (the output model) is required")
    })?;
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let dir = std::env::temp_dir().join(format!("facesim-slicer-{}-{nanos}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| Error::output(&dir, e))?;
    let result = (|| {
        write_case(a, &dir)?;
        let obs = FilterProgress {
            started: AtomicUsize::new(0),
        };
        let outcome = facesim::commands::run(&dir, None, &obs)?;
        write_face(&outcome, dest)?;
        if let Some(l) = &a.landmarks {
            // Landmarks exist once facesim detects them; without them the
            // output is left unwritten and Slicer shows none.
            let src = outcome.out_dir.join("landmarks_post.mrk.json");
            if src.is_file() {
                let bytes = std::fs::read(&src).map_err(|e| Error::input(&src, e))?;
                facesim::output::write_bytes_atomic(l, |w| w.write_all(&bytes))?;
            }
        }
        Ok(())
    })();
    let _ = std::fs::remove_dir_all(&dir);
    result
}

fn main() {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    if argv.iter().any(|a| a == "--xml") {
        print!("{}", xml());
        return;
    }
    if argv.is_empty() || argv.iter().any(|a| a == "--help" || a == "-h") {
        println!(
            "{NAME}: facesim as a 3D Slicer CLI module.\n  {NAME} --xml    print the Slicer Execution Model description\n  {NAME} --ct CT.nrrd --segments SEG.vtk --transforms SEG.tfm --predictedFace FACE.vtp [--face F.vtk] [--movable M.vtk] [--model tet|equilibrium] [--landmarks L.mrk.json]\nSee docs/guide/slicer.md."
        );
        return;
    }
    let args = match parse_args(&argv) {
        Ok(a) => a,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    };
    let start = std::time::Instant::now();
    println!(
        "<filter-start>\n<filter-name>{NAME}</filter-name>\n<filter-comment>predicting the face</filter-comment>\n</filter-start>"
    );
    let _ = std::io::stdout().flush();
    match run(&args) {
        Ok(()) => {
            println!(
                "<filter-progress>1</filter-progress>\n<filter-end>\n<filter-name>{NAME}</filter-name>\n<filter-time>{:.2}</filter-time>\n</filter-end>",
                start.elapsed().as_secs_f64()
            );
        }
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}
