//! OpenSim's `.trc` marker files (the input of OpenSim's inverse kinematics, and of the
//! Pose2Sim and OpenCap pipelines): tab-separated text.
//!
//! ```text
//! PathFileType  4  (X/Y/Z)  trial.trc
//! DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  OrigDataStartFrame  OrigNumFrames
//! 100  100  922  73  mm  100  1  922
//! Frame#  Time  LASI      RASI ...
//!                X1  Y1  Z1  X2  Y2  Z2 ...
//! (a blank line)
//! 1  0  x  y  z  x  y  z ...
//! ```
//!
//! A marker missing in a frame has empty fields (or `NaN`, as some writers put it); a row
//! may stop early, its last markers missing. [`parse`] reads the header's rates, units
//! and original frame range, the marker names, and every row; [`encode`] writes the same
//! layout, with empty fields for a missing marker as OpenSim's `TRCFileAdapter` reads
//! them, and the shortest decimal that reads back as the same `f32`.

/// The markers of a `.trc` file.
#[derive(Clone, Debug, PartialEq)]
pub struct Trc {
    /// The name on the first line (the file's own name, as writers put it).
    pub name: String,
    /// `DataRate`: frames per second of the rows.
    pub rate: f64,
    /// `CameraRate`.
    pub camera_rate: f64,
    /// `Units` (`mm`, `m`, ...).
    pub units: String,
    /// `OrigDataRate`.
    pub orig_rate: f64,
    /// `OrigDataStartFrame`.
    pub orig_start_frame: u64,
    /// `OrigNumFrames`.
    pub orig_frames: u64,
    /// The marker names, `N` of them.
    pub labels: Vec<String>,
    /// `[T]`: each row's `Frame#`.
    pub frame_numbers: Vec<u64>,
    /// `[T]`: each row's `Time` (s).
    pub times: Vec<f64>,
    /// `[T, N, 3]` frame-major; NaN where the marker is missing.
    pub positions: Vec<f32>,
}

impl Trc {
    /// `T`, the rows.
    pub fn frames(&self) -> usize {
        self.times.len()
    }

    /// `N`, the markers.
    pub fn points(&self) -> usize {
        self.labels.len()
    }
}

/// The header keys, in the order writers put them.
const KEYS: [&str; 8] = [
    "DataRate",
    "CameraRate",
    "NumFrames",
    "NumMarkers",
    "Units",
    "OrigDataRate",
    "OrigDataStartFrame",
    "OrigNumFrames",
];

/// Parses the text of a `.trc` file; the error says what is wrong and on which line (the
/// caller adds the file name).
pub fn parse(text: &str) -> Result<Trc, String> {
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')));
    let mut next = |what: &str| {
        lines
            .next()
            .ok_or_else(|| format!("truncated: the file ends before {what}"))
    };
    let (_, first) = next("its first line")?;
    let first: Vec<&str> = first.split('\t').collect();
    if first[0].trim() != "PathFileType" {
        return Err(format!(
            "not a .trc file: its first line starts with {:?}, not PathFileType",
            first[0].chars().take(40).collect::<String>()
        ));
    }
    let name = first.get(3).map_or("", |s| s.trim()).to_string();
    let (_, keys) = next("the header's keys")?;
    let (at, values) = next("the header's values")?;
    let keys: Vec<&str> = keys.split('\t').map(str::trim).collect();
    let values: Vec<&str> = values.split('\t').map(str::trim).collect();
    let value = |key: &str| -> Result<&str, String> {
        keys.iter()
            .position(|k| k.eq_ignore_ascii_case(key))
            .and_then(|i| values.get(i).copied())
            .ok_or_else(|| format!("line {at}: the header has no {key}"))
    };
    let number = |key: &str| -> Result<f64, String> {
        let v = value(key)?;
        v.parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("line {at}: {key} is {v:?}, not a number"))
    };
    let count = |key: &str| -> Result<u64, String> {
        let v = number(key)?;
        if v < 0.0 || v.fract() != 0.0 {
            return Err(format!("line {at}: {key} is {v}, not a count"));
        }
        Ok(v as u64)
    };
    let rate = number("DataRate")?;
    if rate <= 0.0 {
        return Err(format!("line {at}: DataRate is {rate}"));
    }
    let camera_rate = number("CameraRate").unwrap_or(rate);
    let units = value("Units")?.to_string();
    let stated_frames = count("NumFrames")?;
    let stated_markers = count("NumMarkers")?;
    let orig_rate = number("OrigDataRate").unwrap_or(rate);
    let orig_start_frame = count("OrigDataStartFrame").unwrap_or(1);
    let orig_frames = count("OrigNumFrames").unwrap_or(stated_frames);

    let (at, names) = next("the marker names")?;
    let names: Vec<&str> = names.split('\t').collect();
    if names.len() < 2 || names[0].trim() != "Frame#" {
        return Err(format!(
            "line {at}: the marker names' line starts with {:?}, not Frame# and Time",
            names[0]
        ));
    }
    let labels: Vec<String> = names[2..]
        .iter()
        .map(|s| s.trim())
        .filter(|s| !s.is_empty())
        .map(String::from)
        .collect();
    if labels.len() as u64 != stated_markers {
        return Err(format!(
            "line {at}: {} marker names where NumMarkers says {stated_markers}",
            labels.len()
        ));
    }
    let n = labels.len();
    if n == 0 {
        return Err(format!("line {at}: no markers"));
    }
    next("the coordinate names")?;

    let mut frame_numbers = Vec::new();
    let mut times = Vec::new();
    // Bounded by the text: each value takes at least a tab.
    let mut positions = Vec::with_capacity((text.len() / 2).min(3 * n * stated_frames as usize));
    for (at, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split('\t').collect();
        if fields.len() > 2 + 3 * n && fields[2 + 3 * n..].iter().any(|f| !f.trim().is_empty()) {
            return Err(format!(
                "line {at}: {} values where {n} markers have {}",
                fields.len() - 2,
                3 * n
            ));
        }
        let frame = fields[0].trim();
        let frame = frame
            .parse::<u64>()
            .ok()
            .or_else(|| {
                frame
                    .parse::<f64>()
                    .ok()
                    .filter(|f| f.fract() == 0.0 && *f >= 0.0)
                    .map(|f| f as u64)
            })
            .ok_or_else(|| format!("line {at}: the frame number {frame:?} is not a count"))?;
        let time = fields.get(1).map_or("", |s| s.trim());
        let time = time
            .parse::<f64>()
            .ok()
            .filter(|t| t.is_finite())
            .ok_or_else(|| format!("line {at}: the time {time:?} is not a number"))?;
        frame_numbers.push(frame);
        times.push(time);
        for k in 0..3 * n {
            let field = fields.get(2 + k).map_or("", |s| s.trim());
            let v = if field.is_empty() {
                f32::NAN
            } else {
                field.parse::<f32>().map_err(|_| {
                    format!(
                        "line {at}: {field:?} for {} {} is not a number",
                        labels[k / 3],
                        ["X", "Y", "Z"][k % 3]
                    )
                })?
            };
            if v.is_infinite() {
                return Err(format!(
                    "line {at}: {} {} is {v}",
                    labels[k / 3],
                    ["X", "Y", "Z"][k % 3]
                ));
            }
            positions.push(v);
        }
    }
    if times.is_empty() {
        return Err("no frames: the file ends after its header".into());
    }
    if times.len() as u64 != stated_frames {
        return Err(format!(
            "{} rows of frames where NumFrames says {stated_frames}",
            times.len()
        ));
    }
    // A marker is missing whole: one coordinate missing makes the three so.
    for p in positions.chunks_exact_mut(3) {
        if p.iter().any(|v| v.is_nan()) {
            p.fill(f32::NAN);
        }
    }
    Ok(Trc {
        name,
        rate,
        camera_rate,
        units,
        orig_rate,
        orig_start_frame,
        orig_frames,
        labels,
        frame_numbers,
        times,
        positions,
    })
}

/// The text of `trc` as a `.trc` file. Refuses what the layout cannot hold: a marker
/// name with a tab or a line break, counts that do not match, a coordinate or time that
/// is not finite (a missing marker is NaN, written as empty fields).
pub fn encode(trc: &Trc) -> Result<String, String> {
    let (t, n) = (trc.frames(), trc.points());
    if t == 0 || n == 0 {
        return Err(format!("{t} frames of {n} markers: nothing to write"));
    }
    if trc.positions.len() != 3 * t * n || trc.frame_numbers.len() != t {
        return Err(format!(
            "{} coordinates and {} frame numbers for {t} frames of {n} markers",
            trc.positions.len(),
            trc.frame_numbers.len()
        ));
    }
    let plain = |s: &str| !s.contains(['\t', '\n', '\r']);
    if let Some(bad) = trc.labels.iter().find(|l| !plain(l) || l.trim().is_empty()) {
        return Err(format!(
            "the marker name {bad:?} is empty or holds a tab or a line break"
        ));
    }
    if !plain(&trc.name) || !plain(&trc.units) {
        return Err("the file name or the units hold a tab or a line break".into());
    }
    if let Some(v) = trc.positions.iter().find(|v| v.is_infinite()) {
        return Err(format!("a coordinate is {v}"));
    }
    if let Some(v) = trc.times.iter().find(|v| !v.is_finite()) {
        return Err(format!("a time is {v}"));
    }
    let mut out = String::with_capacity(t * n * 30 + 1024);
    out.push_str(&format!("PathFileType\t4\t(X/Y/Z)\t{}\n", trc.name));
    out.push_str(&KEYS.join("\t"));
    out.push('\n');
    out.push_str(&format!(
        "{}\t{}\t{t}\t{n}\t{}\t{}\t{}\t{}\n",
        trc.rate, trc.camera_rate, trc.units, trc.orig_rate, trc.orig_start_frame, trc.orig_frames
    ));
    out.push_str("Frame#\tTime");
    for label in &trc.labels {
        out.push_str(&format!("\t{label}\t\t"));
    }
    out.push_str("\n\t");
    for i in 1..=n {
        out.push_str(&format!("\tX{i}\tY{i}\tZ{i}"));
    }
    out.push_str("\n\n");
    for (f, row) in trc.positions.chunks_exact(3 * n).enumerate() {
        out.push_str(&format!("{}\t{}", trc.frame_numbers[f], trc.times[f]));
        for v in row {
            out.push('\t');
            if !v.is_nan() {
                out.push_str(&v.to_string());
            }
        }
        out.push('\n');
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Trc {
        Trc {
            name: "trial.trc".into(),
            rate: 100.0,
            camera_rate: 100.0,
            units: "mm".into(),
            orig_rate: 100.0,
            orig_start_frame: 7,
            orig_frames: 3,
            labels: vec!["LASI".into(), "R ASI".into()],
            frame_numbers: vec![7, 8, 9],
            times: vec![0.06, 0.07, 0.08],
            positions: vec![
                1.5,
                -2.25,
                3e-7,
                4.0,
                5.0,
                6.0, //
                f32::NAN,
                f32::NAN,
                f32::NAN,
                0.1,
                0.2,
                0.3, //
                7.0,
                8.0,
                9.0,
                1e6,
                -1e-3,
                123.456,
            ],
        }
    }

    fn same(a: &Trc, b: &Trc) -> bool {
        let positions = a
            .positions
            .iter()
            .zip(&b.positions)
            .all(|(x, y)| x.to_bits() == y.to_bits() || x.is_nan() && y.is_nan());
        positions
            && Trc {
                positions: vec![],
                ..a.clone()
            } == Trc {
                positions: vec![],
                ..b.clone()
            }
    }

    #[test]
    fn encode_then_parse_is_the_same_markers() {
        let t = sample();
        let text = encode(&t).unwrap();
        assert!(same(&parse(&text).unwrap(), &t));
        // Windows line ends, NaN spelled out and a row cut short read the same.
        let crlf = text.replace('\n', "\r\n");
        assert!(same(&parse(&crlf).unwrap(), &t));
        let spelled = text.replace("8\t0.07\t\t\t\t", "8\t0.07\tNaN\tNaN\tNaN\t");
        assert!(same(&parse(&spelled).unwrap(), &t));
    }

    #[test]
    fn a_row_cut_short_misses_its_last_markers() {
        let text = encode(&sample())
            .unwrap()
            .replace("\t0.1\t0.2\t0.3\n", "\n");
        let back = parse(&text).unwrap();
        assert!(back.positions[6..12].iter().all(|v| v.is_nan()));
    }

    #[test]
    fn defects_are_named_with_their_line() {
        let good = encode(&sample()).unwrap();
        let cases = [
            (good.replacen("PathFileType", "Path", 1), "not a .trc file"),
            (good.replacen("\t2\tmm", "\t3\tmm", 1), "NumMarkers says 3"),
            (
                good.replacen("\t3\t2\tmm", "\t4\t2\tmm", 1),
                "NumFrames says 4",
            ),
            (
                good.replace("123.456", "12x"),
                "line 9: \"12x\" for R ASI Z",
            ),
            (good.replace("123.456", "inf"), "R ASI Z is inf"),
            (good.replacen("100\t100", "0\t100", 1), "DataRate is 0"),
            (
                good.lines().take(5).collect::<Vec<_>>().join("\n"),
                "no frames",
            ),
            (
                good.lines().take(2).collect::<Vec<_>>().join("\n"),
                "truncated",
            ),
            (
                format!("{good}10\t0.09\t1\t2\t3\t4\t5\t6\t7\n"),
                "7 values where 2 markers",
            ),
        ];
        for (text, want) in cases {
            let e = parse(&text).unwrap_err();
            assert!(e.contains(want), "{e:?} lacks {want:?}");
        }
        let mut bad = sample();
        bad.labels[0] = "A\tB".into();
        assert!(encode(&bad).unwrap_err().contains("tab"));
    }
}
