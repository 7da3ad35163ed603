//! A simulated depth camera in a line-map world: walls extruded to a
//! height, a floor and a ceiling, boxes and people as clutter, and a
//! depth-dependent noise model (σ growing with z², quantization to
//! millimetres, no data beyond range or at grazing angles). Frames are
//! rendered pixel by pixel against the walls visible from the camera.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use crate::camera::CameraMount;
use crate::camera::{DepthImage, Intrinsics};
use crate::geometry::{Pose2, Real, ray_line};
use crate::linemap::LineMap;
use crate::random::standard_normal;
use crate::visibility::observable_scene;

/// A box standing on the floor (axis-aligned, metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clutter {
    /// Lower corner (x, y).
    pub min: (Real, Real),
    /// Upper corner (x, y).
    pub max: (Real, Real),
    /// Height.
    pub height: Real,
}

/// A person: a vertical cylinder standing on the floor (metres). People
/// move between frames; a frame sees them where they are at its instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Person {
    /// Where they stand (x, y).
    pub centre: (Real, Real),
    /// Half their width.
    pub radius: Real,
    /// Height.
    pub height: Real,
}

/// What stands in the map's rooms besides its walls.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Props<'a> {
    /// Boxes.
    pub boxes: &'a [Clutter],
    /// People.
    pub people: &'a [Person],
}

/// The sensor's noise (defaults after the Kinect/RealSense literature:
/// σ(z) = a·z², 1 mm steps, nothing beyond 8 m or below 12° of grazing).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthNoise {
    /// σ = this × z², metres.
    pub sigma_per_z2: Real,
    /// Farthest valid depth, metres.
    pub max_range: Real,
    /// Surfaces seen at less than this angle (radians) give no data.
    pub min_grazing: Real,
    /// Pixels dropped at random anyway (holes).
    pub dropout: Real,
}

impl Default for DepthNoise {
    fn default() -> Self {
        DepthNoise { sigma_per_z2: 0.0015, max_range: 8.0, min_grazing: 12f64.to_radians(), dropout: 0.02 }
    }
}

/// The camera and the world's vertical extent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthCamera {
    /// Intrinsics; the image is `width` × `height`.
    pub intrinsics: Intrinsics,
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Where it sits on the robot.
    pub mount: CameraMount,
    /// Wall height, metres.
    pub wall_height: Real,
    /// Ceiling height, if the room has one.
    pub ceiling: Option<Real>,
    /// Noise.
    pub noise: DepthNoise,
}

impl DepthCamera {
    /// A 640 × 480 camera like the D435, 0.8 m up, level, 2.5 m walls and
    /// ceiling.
    pub fn d435_on_robot() -> Self {
        DepthCamera {
            intrinsics: Intrinsics::D435,
            width: 640,
            height: 480,
            mount: CameraMount { x: 0.0, y: 0.0, height: 0.8, tilt: 0.0, yaw: 0.0 },
            wall_height: 2.5,
            ceiling: Some(2.5),
            noise: DepthNoise::default(),
        }
    }

    /// A frame seen from robot pose `robot`; noise from `rng`.
    pub fn render(&self, map: &LineMap, props: Props<'_>, robot: &Pose2, rng: &mut ChaCha8Rng) -> DepthImage {
        let k = self.intrinsics;
        let m = self.mount;
        let eye = robot.compose(&Pose2::new(m.x, m.y, m.yaw));
        let walls: Vec<u32> = {
            let mut ids: Vec<u32> = observable_scene(map, (eye.x, eye.y), self.noise.max_range + 1.0)
                .iter()
                .map(|v| v.line)
                .collect();
            ids.sort_unstable();
            ids.dedup();
            ids
        };
        let (st, ct) = m.tilt.sin_cos();
        let (sh, ch) = eye.theta.sin_cos();
        let mut depth_mm = vec![0u16; self.width * self.height];
        for row in 0..self.height {
            for col in 0..self.width {
                // The pixel's ray in camera axes (z forward, unit depth).
                let (cx, cy) = ((col as Real - k.cx) / k.fx, (row as Real - k.cy) / k.fy);
                // Robot-level axes: forward, left, up (pitched down by tilt).
                let forward = ct - cy * st;
                let up = -(st + cy * ct);
                let left = -cx;
                // World direction (per unit of camera depth z).
                let (dx, dy) = (ch * forward - sh * left, sh * forward + ch * left);
                let Some((t, cos_incidence)) =
                    self.hit(map, &walls, props, (eye.x, eye.y), (dx, dy, up), m.height)
                else {
                    continue;
                };
                // t is the camera depth z (the ray is scaled to z = 1).
                let z = t;
                let n = &self.noise;
                if z > n.max_range || cos_incidence < n.min_grazing.sin() || rng.random::<Real>() < n.dropout
                {
                    continue;
                }
                let noisy = z + n.sigma_per_z2 * z * z * standard_normal(rng);
                depth_mm[row * self.width + col] = (noisy * 1000.0).round().clamp(1.0, 65535.0) as u16;
            }
        }
        DepthImage { width: self.width, height: self.height, depth_mm }
    }

    /// The nearest surface along the ray from `eye` (horizontal position),
    /// `h` metres up, in direction `d` (per unit camera depth): (depth,
    /// |cos| of the angle between ray and surface normal).
    fn hit(
        &self,
        map: &LineMap,
        walls: &[u32],
        props: Props<'_>,
        eye: (Real, Real),
        d: (Real, Real, Real),
        h: Real,
    ) -> Option<(Real, Real)> {
        let norm = (d.0 * d.0 + d.1 * d.1 + d.2 * d.2).sqrt();
        let mut best: Option<(Real, Real)> = None;
        let mut take = |t: Real, cos: Real| {
            if t > 1e-6 && best.is_none_or(|b| t < b.0) {
                best = Some((t, cos));
            }
        };
        // Floor and ceiling.
        if d.2 < 0.0 {
            take(-h / d.2, d.2.abs() / norm);
        }
        if let Some(c) = self.ceiling
            && d.2 > 0.0
        {
            take((c - h) / d.2, d.2 / norm);
        }
        // A vertical face from `a` to `c`, floor to `top`.
        let mut face = |a: (Real, Real), c: (Real, Real), top: Real| {
            let Some((t, u)) = ray_line(eye, (d.0, d.1), a, c) else { return };
            let z = h + t * d.2;
            if (0.0..=1.0).contains(&u) && (0.0..=top).contains(&z) {
                let (ex, ey) = (c.0 - a.0, c.1 - a.1);
                take(t, ((d.0 * -ey + d.1 * ex) / ((ex * ex + ey * ey).sqrt() * norm)).abs());
            }
        };
        for &i in walls {
            let w = &map.walls[i as usize];
            face(w.a, w.b, self.wall_height);
        }
        // Boxes: their four sides and their top.
        for b in props.boxes {
            let corners = [(b.min.0, b.min.1), (b.max.0, b.min.1), (b.max.0, b.max.1), (b.min.0, b.max.1)];
            for s in 0..4 {
                face(corners[s], corners[(s + 1) % 4], b.height);
            }
        }
        for b in props.boxes {
            if d.2 < 0.0 && h > b.height {
                let t = (b.height - h) / d.2;
                let (x, y) = (eye.0 + t * d.0, eye.1 + t * d.1);
                if x >= b.min.0 && x <= b.max.0 && y >= b.min.1 && y <= b.max.1 {
                    take(t, d.2.abs() / norm);
                }
            }
        }
        // People: the near side of each cylinder, floor to head.
        let horizontal2 = d.0 * d.0 + d.1 * d.1;
        for p in props.people {
            let (ox, oy) = (eye.0 - p.centre.0, eye.1 - p.centre.1);
            let b = ox * d.0 + oy * d.1;
            let disc = b * b - horizontal2 * (ox * ox + oy * oy - p.radius * p.radius);
            if disc <= 0.0 || horizontal2 == 0.0 {
                continue;
            }
            let t = (-b - disc.sqrt()) / horizontal2;
            let z = h + t * d.2;
            if (0.0..=p.height).contains(&z) {
                let (nx, ny) = ((ox + t * d.0) / p.radius, (oy + t * d.1) / p.radius);
                take(t, (nx * d.0 + ny * d.1).abs() / norm);
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;

    use super::*;

    fn room() -> LineMap {
        LineMap::parse("room", "0,0,8,0\n8,0,8,6\n8,6,0,6\n0,6,0,0\n").unwrap()
    }

    #[test]
    fn a_noiseless_frame_has_the_walls_where_they_are() {
        let camera = DepthCamera {
            noise: DepthNoise { sigma_per_z2: 0.0, dropout: 0.0, ..DepthNoise::default() },
            ..DepthCamera::d435_on_robot()
        };
        let image = camera.render(
            &room(),
            Props::default(),
            &Pose2::new(2.0, 3.0, 0.0),
            &mut ChaCha8Rng::seed_from_u64(1),
        );
        // The centre pixel looks along +x at the wall x = 8: 6 m.
        assert_eq!(image.depth_mm[240 * 640 + 320], 6000);
        // Low rows see the floor: at row 400 the ray drops (400−240)/615
        // per metre of depth, so it meets the floor (0.8 m down) at
        // z = 0.8 × 615 / 160.
        let z = f64::from(image.depth_mm[400 * 640 + 320]) / 1000.0;
        assert!((z - 0.8 * 615.0 / 160.0).abs() < 0.002, "{z}");
    }

    #[test]
    fn a_person_stands_in_front_of_the_wall() {
        let camera = DepthCamera {
            noise: DepthNoise { sigma_per_z2: 0.0, dropout: 0.0, ..DepthNoise::default() },
            ..DepthCamera::d435_on_robot()
        };
        let robot = Pose2::new(2.0, 3.0, 0.0);
        let people = [Person { centre: (6.0, 3.0), radius: 0.25, height: 1.7 }];
        let props = Props { boxes: &[], people: &people };
        let image = camera.render(&room(), props, &robot, &mut ChaCha8Rng::seed_from_u64(1));
        let depth = |row: usize, col: usize| f64::from(image.depth_mm[row * 640 + col]) / 1000.0;
        // Straight ahead: the near side of the person, 4 m − 0.25 m away.
        assert!((depth(240, 320) - 3.75).abs() < 0.002, "{}", depth(240, 320));
        // Their head (1.7 m, 0.9 m above the camera) at 3.75 m is at row
        // 240 − 0.9 × 615 / 3.75 ≈ 92: below it the person, above it the
        // wall 6 m away.
        assert!((depth(100, 320) - 3.75).abs() < 0.002, "{}", depth(100, 320));
        assert_eq!(depth(80, 320), 6.0);
        // The silhouette is as wide as the person: 35 px off the axis is
        // 0.23 m off it at 4 m, still on them; 65 px is 0.42 m, the wall.
        assert!((3.75..4.0).contains(&depth(240, 320 + 35)), "{}", depth(240, 320 + 35));
        assert_eq!(depth(240, 320 + 65), 6.0);
        assert_eq!(depth(240, 320 - 65), 6.0);
    }
}
