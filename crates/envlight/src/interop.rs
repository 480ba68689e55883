//! Conversions between envlight's math types and those of other math crates, each
//! behind an optional feature of the same name (off by default).
//!
//! - `mint`: [`Vec3`] ⇄ `mint::Vector3<f32>`, [`Rotation`] → `mint::RowMatrix3<f32>`,
//!   and `mint::RowMatrix3<f32>` → [`Rotation`] through `TryFrom` (a matrix that
//!   is not a rotation is rejected, as by [`Rotation::from_rows`]). Both types
//!   implement `mint::IntoMint`.
//! - `glam`: [`Vec3`] ⇄ `glam::Vec3`.
//!
//! Every conversion copies the components as they are: the frames agree
//! (right-handed; envlight's z up is the other crate's +z), and `Vec3` conversions
//! neither normalise nor check anything.

#[cfg(feature = "mint")]
mod with_mint {
    use crate::{Error, Rotation, Vec3};

    impl From<mint::Vector3<f32>> for Vec3 {
        #[inline]
        fn from(v: mint::Vector3<f32>) -> Self {
            Self::new(v.x, v.y, v.z)
        }
    }

    impl From<Vec3> for mint::Vector3<f32> {
        #[inline]
        fn from(v: Vec3) -> Self {
            Self {
                x: v.x,
                y: v.y,
                z: v.z,
            }
        }
    }

    impl mint::IntoMint for Vec3 {
        type MintType = mint::Vector3<f32>;
    }

    /// The rows of the matrix are those of [`Rotation::rows`]: applying the rotation
    /// is `d'[i] = rows[i] · d`.
    impl From<Rotation> for mint::RowMatrix3<f32> {
        fn from(r: Rotation) -> Self {
            r.rows().into()
        }
    }

    /// As [`Rotation::from_rows`]: the matrix must be orthonormal with determinant
    /// +1 (to 1e-4); anything else is [`Error::InvalidOption`].
    impl TryFrom<mint::RowMatrix3<f32>> for Rotation {
        type Error = Error;

        fn try_from(m: mint::RowMatrix3<f32>) -> Result<Self, Error> {
            let rows: [[f32; 3]; 3] = m.into();
            Rotation::from_rows(rows).ok_or_else(|| {
                Error::InvalidOption(format!(
                    "matrix with rows {rows:?} is not a rotation \
                     (orthonormal with determinant +1, to 1e-4)"
                ))
            })
        }
    }

    impl mint::IntoMint for Rotation {
        type MintType = mint::RowMatrix3<f32>;
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn vec3_round_trips_through_mint() {
            let v = Vec3::new(1.5, -2.0, 0.25);
            let m: mint::Vector3<f32> = v.into();
            assert_eq!((m.x, m.y, m.z), (1.5, -2.0, 0.25));
            assert_eq!(Vec3::from(m), v);
            // Copied as they are, NaN included: no normalisation, no checks.
            let nan = Vec3::from(mint::Vector3 {
                x: f32::NAN,
                y: 0.0,
                z: 1.0,
            });
            assert!(nan.x.is_nan() && nan.z == 1.0);
        }

        #[test]
        fn rotation_round_trips_through_mint_rows() {
            let r = Rotation::about_z_degrees(90.0);
            let m: mint::RowMatrix3<f32> = r.into();
            let rows: [[f32; 3]; 3] = m.into();
            assert_eq!(rows, r.rows());
            // Row-major: the first column is the image of +x, which a quarter turn
            // about +z sends to +y.
            let image_of_x = Vec3::new(m.x.x, m.y.x, m.z.x);
            assert!((image_of_x - Vec3::new(0.0, 1.0, 0.0)).length() < 1e-6);
            assert_eq!(Rotation::try_from(m).unwrap(), r);
        }

        #[test]
        fn non_rotations_are_rejected() {
            let scaled: mint::RowMatrix3<f32> =
                [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].into();
            let mirror: mint::RowMatrix3<f32> =
                [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].into();
            let nan: mint::RowMatrix3<f32> =
                [[f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].into();
            for m in [scaled, mirror, nan] {
                let err = Rotation::try_from(m).unwrap_err();
                assert!(matches!(err, Error::InvalidOption(_)), "{err}");
                assert!(err.to_string().contains("not a rotation"), "{err}");
            }
        }

        #[test]
        fn into_mint_names_the_mint_types() {
            fn to_mint<T: mint::IntoMint>(t: T) -> T::MintType {
                t.into()
            }
            let v: mint::Vector3<f32> = to_mint(Vec3::new(0.0, 0.0, 1.0));
            assert_eq!(v.z, 1.0);
            let m: mint::RowMatrix3<f32> = to_mint(Rotation::IDENTITY);
            assert_eq!((m.x.x, m.y.y, m.z.z), (1.0, 1.0, 1.0));
        }
    }
}

#[cfg(feature = "glam")]
mod with_glam {
    use crate::Vec3;

    impl From<glam::Vec3> for Vec3 {
        #[inline]
        fn from(v: glam::Vec3) -> Self {
            Self::new(v.x, v.y, v.z)
        }
    }

    impl From<Vec3> for glam::Vec3 {
        #[inline]
        fn from(v: Vec3) -> Self {
            Self::new(v.x, v.y, v.z)
        }
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn vec3_round_trips_through_glam() {
            let v = Vec3::new(1.5, -2.0, 0.25);
            let g: glam::Vec3 = v.into();
            assert_eq!(g, glam::Vec3::new(1.5, -2.0, 0.25));
            assert_eq!(Vec3::from(g), v);
            // The operations agree on the converted values.
            let w = Vec3::new(0.5, 3.0, -1.0);
            assert_eq!(g.dot(w.into()), v.dot(w));
            assert_eq!(Vec3::from(g.cross(w.into())), v.cross(w));
        }
    }
}
