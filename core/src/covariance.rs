//! Small symmetric 3 × 3 matrices for the uncertainty of a planar pose
//! (x, y, θ): covariances and information matrices, with the few
//! operations a Gaussian pose needs (sum, product, inverse, Cholesky
//! factor, determinant). Written out by hand: three rows do not need a
//! linear-algebra crate, and nothing here allocates.

use crate::geometry::Real;

/// A 3 × 3 matrix, row-major; as a covariance, over (x m, y m, θ rad).
pub type Mat3 = [[Real; 3]; 3];

/// The zero matrix.
pub const ZERO: Mat3 = [[0.0; 3]; 3];

/// The identity.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The diagonal matrix with `v` on its diagonal.
pub fn diagonal(v: [Real; 3]) -> Mat3 {
    [[v[0], 0.0, 0.0], [0.0, v[1], 0.0], [0.0, 0.0, v[2]]]
}

/// `s · a`.
pub fn scale(a: &Mat3, s: Real) -> Mat3 {
    a.map(|row| row.map(|v| v * s))
}

/// `a + b`.
pub fn add(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[i][j] + b[i][j]))
}

/// `a · b`.
pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

/// `aᵀ`.
pub fn transpose(a: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

/// `a · v`.
pub fn apply(a: &Mat3, v: [Real; 3]) -> [Real; 3] {
    std::array::from_fn(|i| a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2])
}

/// `vᵀ · a · v`.
pub fn quadratic(a: &Mat3, v: [Real; 3]) -> Real {
    let av = apply(a, v);
    v[0] * av[0] + v[1] * av[1] + v[2] * av[2]
}

/// The determinant.
pub fn determinant(a: &Mat3) -> Real {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

/// The inverse, or `None` when `a` is singular (or nearly: its
/// determinant is not above `1e-300` in magnitude, or not finite).
pub fn inverse(a: &Mat3) -> Option<Mat3> {
    let det = determinant(a);
    if !det.is_finite() || det.abs() <= 1e-300 {
        return None;
    }
    let c = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]
    };
    // The inverse is the transposed cofactor matrix over the determinant
    // (the cyclic index order gives the cofactors their signs).
    Some(std::array::from_fn(|i| std::array::from_fn(|j| c(j, i) / det)))
}

/// The lower Cholesky factor `L` with `L · Lᵀ = a` of a symmetric
/// positive semi-definite `a`; pivots that rounding leaves at or below
/// zero become zero (a direction without spread).
pub fn cholesky(a: &Mat3) -> Mat3 {
    let mut l = ZERO;
    for i in 0..3 {
        for j in 0..=i {
            let s: Real = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<Real>();
            if i == j {
                l[i][i] = s.max(0.0).sqrt();
            } else {
                l[i][j] = if l[j][j] > 0.0 { s / l[j][j] } else { 0.0 };
            }
        }
    }
    l
}

/// `(a + aᵀ) / 2`: the symmetric part, to keep rounding from making a
/// covariance lopsided.
pub fn symmetric(a: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (a[i][j] + a[j][i]) / 2.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: Mat3 = [[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]];

    fn close(a: &Mat3, b: &Mat3) -> bool {
        (0..3).all(|i| (0..3).all(|j| (a[i][j] - b[i][j]).abs() < 1e-12))
    }

    #[test]
    fn inverse_and_cholesky_reproduce_the_matrix() {
        let inv = inverse(&A).unwrap();
        assert!(close(&mul(&A, &inv), &IDENTITY));
        assert!(close(&mul(&inv, &A), &IDENTITY));
        let l = cholesky(&A);
        assert!(close(&mul(&l, &transpose(&l)), &A));
        assert_eq!((l[0][1], l[0][2], l[1][2]), (0.0, 0.0, 0.0));
        assert!(
            (determinant(&A) - (4.0 * (6.0 - 0.04) - 1.0 * (2.0 - 0.1) + 0.5 * (0.2 - 1.5))).abs() < 1e-12
        );
        assert!((quadratic(&A, [1.0, 0.0, 1.0]) - (4.0 + 2.0 * 0.5 + 2.0)).abs() < 1e-12);
    }

    #[test]
    fn singular_matrices_have_no_inverse_and_a_flat_factor() {
        let flat = [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 2.0]];
        assert!(inverse(&flat).is_none());
        assert!(inverse(&[[Real::NAN; 3]; 3]).is_none());
        let l = cholesky(&flat);
        assert!(close(&mul(&l, &transpose(&l)), &flat));
        assert_eq!(l[1], [0.0, 0.0, 0.0]);
    }
}
