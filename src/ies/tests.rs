use super::*;
use rand::{RngExt, SeedableRng};

fn p() -> &'static Path {
    Path::new("lamp.ies")
}

fn profile(
    kind: PhotometricType,
    vertical: Vec<f64>,
    horizontal: Vec<f64>,
    seed: u64,
) -> IesProfile {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let candela = (0..vertical.len() * horizontal.len())
        .map(|_| (rng.random_range(0.0..2000.0f64) * 8.0).round() / 8.0)
        .collect();
    IesProfile {
        version: "IESNA:LM-63-2002".into(),
        keywords: vec![
            ("TEST".into(), "T-1".into()),
            ("MANUFAC".into(), "arlux".into()),
        ],
        tilt: None,
        lamps: 1,
        lumens_per_lamp: -1.0,
        multiplier: 1.0,
        photometric_type: kind,
        units: 2,
        width: 0.1,
        length: 0.1,
        height: 0.0,
        ballast_factor: 1.0,
        ballast_lamp_factor: 1.0,
        input_watts: 40.0,
        vertical,
        horizontal,
        candela,
    }
}

fn range(a: f64, b: f64, step: f64) -> Vec<f64> {
    let n = ((b - a) / step).round() as usize;
    (0..=n).map(|i| a + i as f64 * step).collect()
}

fn all_symmetries() -> Vec<IesProfile> {
    use PhotometricType::*;
    vec![
        profile(C, range(0.0, 180.0, 10.0), vec![0.0], 1),
        profile(C, range(0.0, 90.0, 5.0), range(0.0, 90.0, 22.5), 2),
        profile(C, range(0.0, 180.0, 15.0), range(0.0, 180.0, 30.0), 3),
        profile(C, range(90.0, 180.0, 10.0), range(90.0, 270.0, 45.0), 4),
        profile(C, range(0.0, 180.0, 10.0), range(0.0, 360.0, 20.0), 5),
        profile(B, range(-90.0, 90.0, 10.0), range(0.0, 90.0, 15.0), 6),
        profile(B, range(0.0, 90.0, 10.0), range(-90.0, 90.0, 15.0), 7),
        profile(A, range(-90.0, 90.0, 30.0), range(-90.0, 90.0, 30.0), 8),
    ]
}

#[test]
fn every_symmetry_case_round_trips() {
    for (i, prof) in all_symmetries().into_iter().enumerate() {
        let text = prof.to_lm63();
        let back =
            IesProfile::parse(&text, p()).unwrap_or_else(|e| panic!("case {i}: {e}\n{text}"));
        assert_eq!(back, prof, "case {i}");
    }
    let mut tilted = all_symmetries().remove(1);
    tilted.tilt = Some(Tilt {
        lamp_geometry: 1,
        angles: vec![0.0, 45.0, 90.0],
        factors: vec![1.0, 0.9, 0.7],
    });
    let back = IesProfile::parse(&tilted.to_lm63(), p()).unwrap();
    assert_eq!(back, tilted);
    assert!((back.tilt.unwrap().factor(67.5) - 0.8).abs() < 1e-12);
}

#[test]
fn interpolation_matches_the_table_at_grid_points_and_between() {
    let prof = profile(
        PhotometricType::C,
        range(0.0, 180.0, 10.0),
        range(0.0, 360.0, 20.0),
        11,
    );
    let nv = prof.vertical.len();
    // 360° is the direction of 0° again: the file's two columns of it are checked at 0.
    for (hi, &h) in prof
        .horizontal
        .iter()
        .enumerate()
        .filter(|(_, h)| **h < 360.0)
    {
        for (vi, &v) in prof.vertical.iter().enumerate() {
            assert!(
                (prof.candela(v, h) - prof.candela[hi * nv + vi]).abs() < 1e-9,
                "v {v} h {h}"
            );
        }
    }
    // Midway in both angles: the mean of the four corners.
    let c = |h: usize, v: usize| prof.candela[h * nv + v];
    let mid = (c(0, 0) + c(0, 1) + c(1, 0) + c(1, 1)) / 4.0;
    assert!((prof.candela(5.0, 10.0) - mid).abs() < 1e-9);
}

#[test]
fn symmetric_files_are_unfolded() {
    let q = profile(
        PhotometricType::C,
        range(0.0, 90.0, 5.0),
        range(0.0, 90.0, 22.5),
        2,
    );
    for v in [0.0, 12.5, 45.0, 90.0] {
        for h in [10.0, 30.0, 80.0] {
            let base = q.candela(v, h);
            for mirrored in [180.0 - h, 180.0 + h, 360.0 - h, -h] {
                assert!(
                    (q.candela(v, mirrored) - base).abs() < 1e-9,
                    "v {v} h {h} vs {mirrored}"
                );
            }
        }
    }
    assert_eq!(
        q.candela(120.0, 0.0),
        0.0,
        "a 0-90 file emits nothing upwards"
    );
    let half = profile(
        PhotometricType::C,
        range(0.0, 180.0, 15.0),
        range(0.0, 180.0, 30.0),
        3,
    );
    assert!((half.candela(40.0, 250.0) - half.candela(40.0, 110.0)).abs() < 1e-9);
    let side = profile(
        PhotometricType::C,
        range(90.0, 180.0, 10.0),
        range(90.0, 270.0, 45.0),
        4,
    );
    assert!((side.candela(120.0, 30.0) - side.candela(120.0, 150.0)).abs() < 1e-9);
    assert!((side.candela(120.0, 300.0) - side.candela(120.0, 240.0)).abs() < 1e-9);
    let round = profile(PhotometricType::C, range(0.0, 180.0, 10.0), vec![0.0], 1);
    assert_eq!(round.candela(33.0, 0.0), round.candela(33.0, 217.0));
    let b = profile(
        PhotometricType::B,
        range(-90.0, 90.0, 10.0),
        range(0.0, 90.0, 15.0),
        6,
    );
    assert!((b.candela(20.0, -40.0) - b.candela(20.0, 40.0)).abs() < 1e-9);
}

#[test]
fn integrated_flux_of_a_uniform_file_is_4pi_times_its_candela() {
    let text = "IESNA:LM-63-1995\n[TEST]uniform\nTILT=NONE\n1 -1 2.0 3 1 1 2 0 0 0\n1 1 0\n0 90 180\n0\n50 50 50\n";
    let prof = IesProfile::parse(text, p()).unwrap();
    assert_eq!(
        prof.keywords[0],
        ("TEST".to_string(), "uniform".to_string()),
        "no space after the bracket"
    );
    // Midpoint rule over the sphere in (cos θ, φ): exact for a constant.
    let (n, m) = (200, 64);
    let mut flux = 0.0;
    for i in 0..n {
        let z = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
        for j in 0..m {
            let phi = (j as f64 + 0.5) * std::f64::consts::TAU / m as f64;
            let s = (1.0 - z * z).sqrt();
            let d = DVec3::new(s * phi.cos(), s * phi.sin(), z);
            flux += prof.candela_towards(d, DVec3::Z, DVec3::X)
                * (2.0 / n as f64)
                * (std::f64::consts::TAU / m as f64);
        }
    }
    assert!(
        (flux - 4.0 * std::f64::consts::PI * 100.0).abs() < 1e-6,
        "{flux}"
    );
}

#[test]
fn values_may_be_split_across_lines_in_any_way() {
    let prof = profile(
        PhotometricType::C,
        range(0.0, 90.0, 30.0),
        range(0.0, 180.0, 90.0),
        21,
    );
    let text = prof.to_lm63();
    let (head, data) = text.split_once("TILT=NONE\n").unwrap();
    let numbers: Vec<&str> = data.split_whitespace().collect();
    let one_per_line = format!("{head}TILT=NONE\n{}\n", numbers.join("\n"));
    let one_line_commas = format!("{head}TILT=NONE\n{}\n", numbers.join(", "));
    assert_eq!(IesProfile::parse(&one_per_line, p()).unwrap(), prof);
    assert_eq!(IesProfile::parse(&one_line_commas, p()).unwrap(), prof);
    // A 1986 file: no version line, free label lines; and a 2019 file with CRLF.
    let old = format!("Some lamp, 1986\n{}", text.split_once('\n').unwrap().1);
    assert_eq!(IesProfile::parse(&old, p()).unwrap().version, "");
    let crlf = text
        .replace("IESNA:LM-63-2002", "IES:LM-63-2019")
        .replace('\n', "\r\n");
    assert_eq!(IesProfile::parse(&crlf, p()).unwrap().candela, prof.candela);
    let inline_tilt = format!("{head}TILT=INCLUDE\n1\n3\n0 45 90\n1 0.9\n0.8\n{}", data);
    assert_eq!(
        IesProfile::parse(&inline_tilt, p())
            .unwrap()
            .tilt
            .unwrap()
            .factors,
        vec![1.0, 0.9, 0.8]
    );
}

#[test]
fn malformed_files_are_reported_with_their_line() {
    let good = "IESNA:LM-63-2002\n[TEST] x\nTILT=NONE\n1 -1 1 3 1 1 2 0 0 0\n1 1 0\n0 45 90\n0\n10 20 30\n";
    assert!(IesProfile::parse(good, p()).is_ok());
    let cases: &[(&str, &str, usize, &str)] = &[
        ("TILT=NONE\n", "", 7, "no TILT= line"),
        ("10 20 30", "10 x 30", 8, "'x' is not a number"),
        (
            "10 20 30",
            "10 20",
            8,
            "the file ends where candela value 3 of 3 should be",
        ),
        (
            "0 45 90",
            "0 90 45",
            6,
            "vertical angle 3 of 3 is 45 after 90: angles must increase (does the header's count of 3 match",
        ),
        ("10 20 30", "10 -20 30", 8, "candela value -20 is negative"),
        (
            "1 -1 1 3 1 1 2",
            "1 -1 1 3 1 7 2",
            4,
            "photometric type must be 1 (C), 2 (B) or 3 (A)",
        ),
        ("10 20 30\n", "10 20 30\n99\n", 9, "unexpected '99'"),
        ("0\n10", "45\n10", 7, "type C horizontal angles 45..45"),
        (
            "1 -1 1 3 1 1 2",
            "1 -1 1 0 1 1 2",
            4,
            "number of vertical angles: must be a positive whole number",
        ),
        (
            "TILT=NONE",
            "TILT=INCLUDE",
            4,
            "number of tilt angles: must be a positive whole number",
        ),
        ("TILT=NONE", "TILT", 3, "TILT line needs '='"),
    ];
    for (old, new, line, message) in cases {
        let text = good.replacen(old, new, 1);
        let e = IesProfile::parse(&text, p()).expect_err(message);
        assert_eq!(
            e.location,
            crate::error::Location::Line(*line),
            "{message}: {e}"
        );
        assert!(e.to_string().contains(message), "{message}: {e}");
        assert!(e.to_string().starts_with("lamp.ies: line"), "{e}");
    }
    assert!(
        IesProfile::parse("\n\n", p())
            .unwrap_err()
            .to_string()
            .contains("empty IES file")
    );
}
