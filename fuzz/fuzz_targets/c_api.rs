#![no_main]
// The C boundary from untrusted input: `envlight_light_from_rgb` with arbitrary
// sizes, options and texels (NaN, infinite, negative, huge), then the batch and
// single calls with arbitrary `u` and directions. Nothing may panic or abort; a
// refused light is a status with a message; a built light answers every query with
// finite values, the batch calls equal the single ones bit for bit, and a drawn
// sample has a positive pdf.
//
// Layout: width (1 + byte % 24), height (1 + byte % 12), then four option bytes
// (sampler, density, mapping, lookup; values past the enums test the option
// checks), then width·height·3 texels as f32 (missing bytes are 0), then the rest
// as f32 queries (pairs of u, triples of directions).
use envlight_c::*;

fn floats(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks(4)
        .map(|c| {
            let mut b = [0u8; 4];
            b[..c.len()].copy_from_slice(c);
            f32::from_le_bytes(b)
        })
        .collect()
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if data.len() < 6 {
        return;
    }
    let (w, h) = (1 + (data[0] % 24) as u32, 1 + (data[1] % 12) as u32);
    let options = envlight_light_options {
        sampler: (data[2] % 4) as u32,
        density: (data[3] % 3) as u32,
        mapping: (data[4] % 3) as u32,
        lookup: (data[5] % 3) as u32,
        ..envlight_light_options_default()
    };
    let texel_bytes = (w * h * 3 * 4) as usize;
    let rest = &data[6..];
    let (texels, queries) = rest.split_at(texel_bytes.min(rest.len()));
    let mut rgb = floats(texels);
    rgb.resize((w * h * 3) as usize, 0.0);
    let mut light = std::ptr::null_mut();
    let status = envlight_light_from_rgb(rgb.as_ptr(), w, h, &options, &mut light);
    if status != envlight_status::ENVLIGHT_OK {
        assert!(light.is_null());
        assert!(envlight_last_error(std::ptr::null_mut(), 0) > 0, "a failure without a message");
        return;
    }
    let q = floats(queries);
    let n = q.len() / 3;
    let (u, dirs) = (&q[..2 * n], &q[..3 * n]);
    let mut samples = vec![envlight_sample::default(); n];
    let mut pdf = vec![0.0f32; n];
    let mut rgb_out = vec![0.0f32; 3 * n];
    assert_eq!(envlight_light_sample_batch(light, u.as_ptr(), n, samples.as_mut_ptr()), envlight_status::ENVLIGHT_OK);
    assert_eq!(envlight_light_pdf_batch(light, dirs.as_ptr(), n, pdf.as_mut_ptr()), envlight_status::ENVLIGHT_OK);
    assert_eq!(envlight_light_radiance_batch(light, dirs.as_ptr(), n, rgb_out.as_mut_ptr()), envlight_status::ENVLIGHT_OK);
    let bits = |s: &envlight_sample| {
        let mut v = s.direction.to_vec();
        v.push(s.pdf);
        v.extend(s.radiance);
        v.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    };
    for k in 0..n {
        let mut s = envlight_sample::default();
        let ok = envlight_light_sample(light, u[2 * k..].as_ptr(), &mut s);
        assert_eq!(bits(&s), bits(&samples[k]), "sample {k}");
        assert_eq!(ok, s.pdf > 0.0);
        assert!(bits(&s).iter().all(|&b| f32::from_bits(b).is_finite()), "{s:?}");
        let p = envlight_light_pdf(light, dirs[3 * k..].as_ptr());
        assert_eq!(p.to_bits(), pdf[k].to_bits());
        assert!(p.is_finite() && p >= 0.0);
        let mut l = [0.0f32; 3];
        envlight_light_radiance(light, dirs[3 * k..].as_ptr(), l.as_mut_ptr());
        assert_eq!(l, rgb_out[3 * k..3 * k + 3]);
        assert!(l.iter().all(|c| c.is_finite() && *c >= 0.0), "{l:?}");
    }
    envlight_light_free(light);
});
