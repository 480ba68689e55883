// The distribution fuzz target's checks, shared with the regression test
// (crates/envlight/tests/fuzz_regressions.rs replays fuzz/regressions/distribution/).
//
// Arbitrary f32 grids (any bit pattern: NaN, infinities, subnormals, negatives)
// through the distributions and the light: no panic, no NaN, and the promises of
// docs/design.md §3 on whatever comes out.

#[allow(dead_code)]
fn check_distribution(data: &[u8]) {
    use envlight::distribution::{Distribution1D, Distribution2D};
    use envlight::{EnvImage, EnvironmentLight, LightOptions, Lookup};

    let Some((&shape, rest)) = data.split_first() else {
        return;
    };
    let values: Vec<f32> = rest
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .take(4096)
        .collect();
    if values.is_empty() {
        return;
    }
    let nu = (shape as usize % values.len()).max(1);
    let n = values.len() / nu * nu;
    let values = &values[..n];

    let d1 = Distribution1D::new(values);
    let d2 = Distribution2D::new(values, nu);
    for k in 0..64u64 {
        let xi = envlight::rng::xi_2d(shape as u64, k);
        let s = d1.sample_continuous(xi[0]);
        assert!((0.0..1.0).contains(&s.x) && s.pdf.is_finite() && s.pdf >= 0.0);
        if d1.integral() > 0.0 {
            let v = values[s.cell];
            assert!(v > 0.0 && v.is_finite(), "sampled a zero cell");
            assert!(s.pdf > 0.0, "a positive cell with pdf 0");
        }
        assert!((0.0..=1.0).contains(&d1.invert(s.x)));
        let s = d2.sample_continuous(xi);
        assert!(s.uv.iter().all(|c| (0.0..1.0).contains(c)));
        assert!(s.pdf.is_finite() && s.pdf >= 0.0);
        assert_eq!(d2.pdf(s.uv), s.pdf);
        if d2.integral() > 0.0 {
            let v = values[s.cell[1] * nu + s.cell[0]];
            assert!(v > 0.0 && v.is_finite(), "sampled a zero cell");
            assert!(s.pdf > 0.0, "a positive cell with pdf 0");
        }
    }

    // The same values as luminance of a grey map (non-finite and negative texels
    // are replaced/clamped the way the loaders do).
    let texels: Vec<[f32; 3]> = values.iter().map(|&v| [v; 3]).collect();
    if let Ok((image, _)) = EnvImage::from_raw("fuzz", nu, n / nu, texels, true) {
        let lookup = if shape & 1 == 0 {
            Lookup::Bilinear
        } else {
            Lookup::Nearest
        };
        let options = LightOptions {
            lookup,
            ..Default::default()
        };
        let light = EnvironmentLight::new(image, options).expect("default options are valid");
        for k in 0..64u64 {
            if let Some(s) = light.sample(envlight::rng::xi_2d(7, k)) {
                assert!(s.pdf > 0.0 && s.pdf.is_finite());
                assert!(s.radiance.iter().all(|c| c.is_finite() && *c >= 0.0));
                assert!(light.pdf(s.direction).is_finite());
            }
        }
        assert!(light.integral_luminance().is_finite());
    }
}
