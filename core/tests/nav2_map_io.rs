//! The map files read back the way nav2's `map_server` reads them
//! (`nav2_map_server/src/map_io.cpp`, `loadMapFromYaml` and
//! `loadMapFromFile`): the image path relative to the YAML, `negate`, the
//! trinary thresholds compared strictly, and image row 0 at the top of the
//! map. A loader written from that description, not from squall's writer,
//! must find every cell's class (free, occupied, unknown) where the grid
//! has it.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use squall_core::map_files::{FREE_PERCENT, OCCUPIED_PERCENT, write_pgm_yaml};
use squall_core::occupancy::{OccupancyGrid, UNKNOWN};

/// `nav_msgs/OccupancyGrid` values, as map_io writes them.
const FREE: i8 = 0;
const OCCUPIED: i8 = 100;
const NO_INFORMATION: i8 = -1;

/// What map_io's `LoadParameters` holds.
struct LoadParameters {
    image: PathBuf,
    resolution: f64,
    origin: [f64; 3],
    negate: bool,
    occupied_thresh: f64,
    free_thresh: f64,
    mode: String,
}

/// The YAML's keys (flat `key: value` lines, as map_saver writes them);
/// `image` relative to the YAML's folder, as map_io resolves it.
fn load_yaml(path: &Path) -> LoadParameters {
    let text = std::fs::read_to_string(path).unwrap();
    let keys: HashMap<&str, &str> = text
        .lines()
        .filter(|line| !line.trim().is_empty() && !line.trim_start().starts_with('#'))
        .map(|line| {
            let (key, value) =
                line.split_once(':').unwrap_or_else(|| panic!("not a key: value line: {line:?}"));
            (key.trim(), value.trim())
        })
        .collect();
    let number =
        |key: &str| -> f64 { keys[key].parse().unwrap_or_else(|_| panic!("{key}: {:?}", keys[key])) };
    let image = Path::new(keys["image"]);
    let origin: Vec<f64> =
        keys["origin"].trim_matches(['[', ']']).split(',').map(|v| v.trim().parse().unwrap()).collect();
    LoadParameters {
        image: if image.is_absolute() { image.to_path_buf() } else { path.parent().unwrap().join(image) },
        resolution: number("resolution"),
        origin: [origin[0], origin[1], origin[2]],
        negate: keys["negate"] != "0",
        occupied_thresh: number("occupied_thresh"),
        free_thresh: number("free_thresh"),
        // map_io's default mode is trinary.
        mode: keys.get("mode").copied().unwrap_or("trinary").to_string(),
    }
}

/// A binary PGM (P5, 8 bit): width, height and the pixels, comments
/// skipped as any netpbm reader does.
fn read_pgm(path: &Path) -> (usize, usize, Vec<u8>) {
    let bytes = std::fs::read(path).unwrap();
    let mut fields = Vec::new();
    let mut at = 0;
    while fields.len() < 4 {
        match bytes[at] {
            b'#' => {
                while bytes[at] != b'\n' {
                    at += 1;
                }
            }
            c if c.is_ascii_whitespace() => {}
            _ => {
                let start = at;
                while !bytes[at].is_ascii_whitespace() {
                    at += 1;
                }
                fields.push(String::from_utf8(bytes[start..at].to_vec()).unwrap());
                continue;
            }
        }
        at += 1;
    }
    assert_eq!(fields[0], "P5");
    assert_eq!(fields[3], "255");
    let (width, height) = (fields[1].parse().unwrap(), fields[2].parse().unwrap());
    // One whitespace byte ends the header.
    let pixels = bytes[at + 1..].to_vec();
    assert_eq!(pixels.len(), width * height);
    (width, height, pixels)
}

/// map_io's `loadMapFromFile` for a grey image in trinary mode: the
/// occupancy grid's data, row 0 at the bottom.
fn load_like_map_server(yaml: &Path) -> (LoadParameters, usize, usize, Vec<i8>) {
    let parameters = load_yaml(yaml);
    assert_eq!(parameters.mode, "trinary");
    let (width, height, pixels) = read_pgm(&parameters.image);
    let mut data = vec![NO_INFORMATION; width * height];
    for y in 0..height {
        for x in 0..width {
            let shade = f64::from(pixels[y * width + x]) / 255.0;
            let occ = if parameters.negate { shade } else { 1.0 - shade };
            let cell = if parameters.occupied_thresh < occ {
                OCCUPIED
            } else if occ < parameters.free_thresh {
                FREE
            } else {
                NO_INFORMATION
            };
            data[width * (height - y - 1) + x] = cell;
        }
    }
    (parameters, width, height, data)
}

/// The class a planner should see for an occupancy of `value` percent.
fn class_of(value: i8) -> i8 {
    match value {
        UNKNOWN => NO_INFORMATION,
        v if v >= OCCUPIED_PERCENT => OCCUPIED,
        v if v <= FREE_PERCENT => FREE,
        _ => NO_INFORMATION,
    }
}

fn counts(cells: impl Iterator<Item = i8>) -> [usize; 3] {
    let mut n = [0; 3];
    for c in cells {
        n[match c {
            FREE => 0,
            OCCUPIED => 1,
            _ => 2,
        }] += 1;
    }
    n
}

#[test]
fn map_server_loads_free_occupied_and_unknown_where_the_grid_has_them() {
    // A grid that is not square, off the origin, with every occupancy
    // value and mostly unknown cells, as a map early in a run is.
    let (width, height) = (37, 23);
    let mut grid = OccupancyGrid::unknown(width, height, 0.05, (-3.25, 7.5));
    let mut rng = ChaCha8Rng::seed_from_u64(0x6d61_7073);
    for y in 0..height {
        for x in 0..width {
            if rng.random_bool(0.4) {
                grid.set(x, y, rng.random_range(0..=100));
            }
        }
    }
    // The thresholds' edges themselves.
    for (x, value) in
        [(0, FREE_PERCENT), (1, FREE_PERCENT + 1), (2, OCCUPIED_PERCENT - 1), (3, OCCUPIED_PERCENT)]
    {
        grid.set(x, 0, value);
    }
    let dir = tempfile::tempdir().unwrap();
    let maps = dir.path().join("maps");
    std::fs::create_dir(&maps).unwrap();
    write_pgm_yaml(&grid, &maps, "map").unwrap();

    let (parameters, w, h, data) = load_like_map_server(&maps.join("map.yaml"));
    assert_eq!((w, h), (width, height));
    assert_eq!(parameters.resolution, 0.05);
    assert_eq!(parameters.origin, [-3.25, 7.5, 0.0]);
    let expected: Vec<i8> = grid.cells.iter().map(|&v| class_of(v)).collect();
    let [free, occupied, unknown] = counts(expected.iter().copied());
    assert!(free > 0 && occupied > 0 && unknown > width * height / 2, "{free} {occupied} {unknown}");
    assert_eq!(counts(data.iter().copied()), [free, occupied, unknown]);
    for (i, (&loaded, &want)) in data.iter().zip(&expected).enumerate() {
        assert_eq!(loaded, want, "cell ({}, {}) of occupancy {}", i % width, i / width, grid.cells[i]);
    }
}
