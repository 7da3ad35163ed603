//! The CARMEN reader on the real logs in `../shared/data/laser`, gzip,
//! truncation, and a mutation fuzz of the line parser.

mod common;
use common::shared;

use std::io::Write;

use squall_spouts::carmen::{Laser, LineParser, LogError, ReadOptions, Record, count_front_scans, read_log};

fn front_scans(records: &[Record]) -> usize {
    records.iter().filter(|r| matches!(r, Record::Scan(Laser::Front, _))).count()
}

#[test]
fn every_real_log_parses_completely() {
    for (file, scans, range_max) in [
        ("laser/aces.clf", 7374, 50.0),
        ("laser/intel.clf", 13631, 80.0),
        ("laser/mit-csail.clf", 1988, 80.0),
    ] {
        let records = read_log(&shared(file), ReadOptions::default()).unwrap();
        assert_eq!(front_scans(&records), scans, "{file}");
        // The progress display's quick count agrees with the parse.
        assert_eq!(count_front_scans(&shared(file)).unwrap(), scans as u64, "{file}");
        let Some(Record::Scan(_, first)) = records.iter().find(|r| matches!(r, Record::Scan(..))) else {
            panic!("{file}: no scan")
        };
        assert_eq!(first.range_max, range_max, "{file}");
        assert!(
            (first.angle_increment - std::f64::consts::PI / (first.ranges.len() - 1) as f64).abs() < 1e-6
        );
    }
}

#[test]
fn gzip_reads_the_same_and_truncation_is_an_error() {
    let plain = shared("laser/mit-csail.clf");
    let bytes = std::fs::read(&plain).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let gz = dir.path().join("csail.clf.gz");
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(&bytes).unwrap();
    let compressed = enc.finish().unwrap();
    std::fs::write(&gz, &compressed).unwrap();
    let a = read_log(&plain, ReadOptions::default()).unwrap();
    let b = read_log(&gz, ReadOptions::default()).unwrap();
    assert_eq!(a, b);
    assert_eq!(count_front_scans(&gz).unwrap(), front_scans(&a) as u64);

    let cut = dir.path().join("cut.clf.gz");
    std::fs::write(&cut, &compressed[..compressed.len() / 2]).unwrap();
    match read_log(&cut, ReadOptions::default()) {
        Err(LogError::Read { line, .. }) => assert!(line > 100, "line {line}"),
        other => panic!("a truncated gzip stream must be an error, got {:?}", other.map(|r| r.len())),
    }
}

#[test]
fn a_cut_off_last_line_is_an_error_with_its_line() {
    let text = std::fs::read_to_string(shared("laser/mit-csail.clf")).unwrap();
    let cut_at = text.len() - 400;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.clf");
    std::fs::write(&path, &text[..cut_at]).unwrap();
    let last_line = text[..cut_at].lines().count();
    match read_log(&path, ReadOptions::default()) {
        Err(e @ LogError::Bad { .. }) => {
            let message = e.to_string();
            assert!(message.starts_with(&format!("{}:{last_line}: FLASER", path.display())), "{message}");
            assert!(message.contains("line cut off?"), "{message}");
        }
        other => panic!("expected a malformed-record error, got {:?}", other.map(|r| r.len())),
    }
    // With skip_bad the rest is read and the bad record counted.
    let mut reader =
        squall_spouts::carmen::LogReader::open(&path, ReadOptions { skip_bad: true, ..Default::default() })
            .unwrap();
    let n = reader.by_ref().filter(|r| matches!(r, Ok(Record::Scan(..)))).count();
    assert_eq!(n, 1987);
    assert_eq!(reader.skipped(), 1);
}

/// Deterministic mutation fuzz: cut, splice and corrupt real lines; the
/// parser must answer Ok or Err, never panic.
#[test]
fn the_line_parser_never_panics() {
    let text = std::fs::read_to_string(shared("laser/aces.clf")).unwrap();
    let lines: Vec<&str> = text.lines().take(400).collect();
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut rand = move |n: usize| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % n as u64) as usize
    };
    let junk = ["", "nan", "inf", "-", "1e999", "99999999999999999999", "\u{fffd}", "FLASER", "0", "-3"];
    let mut parser = LineParser::new(80.0);
    let (mut ok, mut err) = (0, 0);
    for _ in 0..20_000 {
        let mut tokens: Vec<String> = lines[rand(lines.len())].split(' ').map(str::to_string).collect();
        match rand(4) {
            0 => tokens.truncate(rand(tokens.len() + 1)),
            1 => {
                let i = rand(tokens.len());
                tokens[i] = junk[rand(junk.len())].to_string();
            }
            2 => {
                let other: Vec<&str> = lines[rand(lines.len())].split(' ').collect();
                let cut = rand(other.len());
                tokens.extend(other[cut..].iter().map(|s| s.to_string()));
            }
            _ => {
                let i = rand(tokens.len());
                tokens.insert(i, junk[rand(junk.len())].to_string());
            }
        }
        match parser.parse(&tokens.join(" ")) {
            Ok(_) => ok += 1,
            Err(_) => err += 1,
        }
    }
    assert!(ok > 1000 && err > 1000, "the fuzz should hit both outcomes: ok {ok}, err {err}");
}
