//! Reading a GPU tables file back, checking everything a shader relies on.

use super::*;

/// A known section's entry in the section table.
#[derive(Debug, Clone, Copy)]
struct Entry {
    element: ElementType,
    byte_offset: usize,
    byte_len: usize,
    count: u64,
}

/// The little-endian `u32` at byte `at` (the caller checked the bounds).
pub(super) fn u32_at(bytes: &[u8], at: usize) -> u32 {
    let mut b = [0u8; 4];
    b.copy_from_slice(&bytes[at..at + 4]);
    u32::from_le_bytes(b)
}

/// The little-endian `u64` at byte `at` (the caller checked the bounds).
pub(super) fn u64_at(bytes: &[u8], at: usize) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&bytes[at..at + 8]);
    u64::from_le_bytes(b)
}

/// `n` words from byte `at` (the caller checked the bounds).
pub(super) fn words_at(bytes: &[u8], at: usize, n: usize) -> Vec<u32> {
    bytes[at..at + 4 * n]
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// [`GpuTables::from_bytes`], with the detail of the error.
pub(super) fn parse(bytes: &[u8]) -> std::result::Result<GpuTables, String> {
    let len = bytes.len();
    if len < HEADER_BYTES {
        return Err(format!(
            "truncated: {len} bytes, shorter than the {HEADER_BYTES}-byte header"
        ));
    }
    if bytes[..8] != MAGIC {
        return Err(format!(
            "bad magic number {:02x?}: not an envlight GPU tables file (expected \"ENVLGPU\\0\")",
            &bytes[..8]
        ));
    }
    let version = u32_at(bytes, 8);
    if version != VERSION {
        return Err(format!(
            "layout version {version}, but this reader knows version {VERSION} only"
        ));
    }
    let entries = find_sections(bytes)?;
    let params_entry = entries[section::PARAMS as usize].ok_or("no params section (id 1)")?;
    if params_entry.element != ElementType::U32 || params_entry.count != PARAMS_WORDS as u64 {
        return Err(format!(
            "the params section holds {} {} elements, not {PARAMS_WORDS} u32",
            params_entry.count,
            params_entry.element.name()
        ));
    }
    let mut params = [0u32; PARAMS_WORDS];
    params.copy_from_slice(&words_at(bytes, params_entry.byte_offset, PARAMS_WORDS));
    let expected = expected_sampling(&params)?;

    // The sampling sections: exactly those the parameters call for, contiguous in
    // id order from the first, where the parameters say they are.
    let first = expected
        .first()
        .ok_or("the parameters call for no sampling section")?;
    let first_entry = entries[first.id as usize].ok_or_else(|| missing(first.id, &params))?;
    let tables_at = first_entry.byte_offset;
    for id in section::SAMPLING {
        let name = section::name(id).unwrap_or("?");
        let entry = entries[id as usize];
        let Some(place) = expected.iter().find(|p| p.id == id) else {
            if entry.is_some() {
                return Err(format!(
                    "section {name} is present, but the parameters ({}) do not use it",
                    describe(&params)
                ));
            }
            continue;
        };
        let entry = entry.ok_or_else(|| missing(id, &params))?;
        if entry.count != place.words as u64 {
            return Err(format!(
                "section {name} holds {} elements, but the parameters' sizes call for {}",
                entry.count, place.words
            ));
        }
        let want = tables_at as u64 + 4 * place.word_offset as u64;
        if entry.byte_offset as u64 != want {
            return Err(format!(
                "section {name} starts at byte {}, but the tables buffer (from byte \
                 {tables_at}) puts it at {want}: the sampling sections must follow each \
                 other in id order, each padded to 16 bytes",
                entry.byte_offset
            ));
        }
    }
    let tables_words = params[param::TABLES_WORDS] as usize;
    let tables_end = tables_at as u64 + 4 * tables_words as u64;
    if tables_end > len as u64 {
        return Err(format!(
            "truncated: the tables buffer runs from byte {tables_at} to {tables_end}, past \
             the end of the file ({len} bytes)"
        ));
    }
    let tables = words_at(bytes, tables_at, tables_words);

    let radiance = entries[section::RADIANCE as usize].ok_or("no radiance section (id 9)")?;
    let (want_element, per_texel) = match params[param::RADIANCE_FORMAT] {
        value::RADIANCE_F32 => (ElementType::F32, 3),
        _ => (ElementType::F16, 4),
    };
    let texels = params[param::IMAGE_WIDTH] as u64 * params[param::IMAGE_HEIGHT] as u64;
    let want_count = texels.saturating_mul(per_texel);
    if radiance.element != want_element || radiance.count != want_count {
        return Err(format!(
            "the radiance section holds {} {} elements, but a {}x{} image in the format \
             the parameters name needs {} {}",
            radiance.count,
            radiance.element.name(),
            params[param::IMAGE_WIDTH],
            params[param::IMAGE_HEIGHT],
            want_count,
            want_element.name()
        ));
    }
    if radiance.byte_offset < tables_at + 4 * tables_words {
        return Err("the radiance section overlaps the tables buffer".into());
    }
    let radiance = words_at(bytes, radiance.byte_offset, radiance.byte_len / 4);
    let out = GpuTables {
        params,
        tables,
        layout: expected,
        radiance,
    };
    check_contents(&out)?;
    Ok(out)
}

/// The section table's known entries, indexed by id, after checking that every
/// entry (known or not) is aligned, in bounds and after the previous one, and
/// that known ones have their element type, a byte length that matches their
/// count, and no duplicate.
fn find_sections(bytes: &[u8]) -> std::result::Result<[Option<Entry>; 10], String> {
    let len = bytes.len() as u64;
    let count = u32_at(bytes, 12) as u64;
    let table_end = HEADER_BYTES as u64 + ENTRY_BYTES as u64 * count;
    if table_end > len {
        return Err(format!(
            "truncated: the section table of {count} entries needs {table_end} bytes, the \
             file has {len}"
        ));
    }
    let mut entries: [Option<Entry>; 10] = [None; 10];
    let mut previous_end = table_end;
    for k in 0..count as usize {
        let at = HEADER_BYTES + ENTRY_BYTES * k;
        let id = u32_at(bytes, at);
        let code = u32_at(bytes, at + 4);
        let byte_offset = u64_at(bytes, at + 8);
        let byte_len = u64_at(bytes, at + 16);
        let elements = u64_at(bytes, at + 24);
        let name = section::name(id);
        let what = match name {
            Some(name) => format!("section {name}"),
            None => format!("section {k} (unknown id {id})"),
        };
        if !byte_offset.is_multiple_of(ALIGN_BYTES as u64) {
            return Err(format!(
                "{what} starts at byte {byte_offset}, not a multiple of 16"
            ));
        }
        if byte_offset < previous_end {
            return Err(format!(
                "{what} starts at byte {byte_offset}, inside the header, the section table \
                 or the section before it (which end at byte {previous_end})"
            ));
        }
        let end = byte_offset.checked_add(byte_len).filter(|&e| e <= len);
        let Some(end) = end else {
            return Err(format!(
                "{what} (byte {byte_offset}, {byte_len} bytes) runs past the end of the \
                 file ({len} bytes): truncated or corrupt"
            ));
        };
        previous_end = end;
        let Some(name) = name else {
            continue;
        };
        let element = ElementType::from_code(code)
            .ok_or_else(|| format!("{what} has unknown element type {code}"))?;
        let allowed = match id {
            section::RADIANCE => element != ElementType::U32,
            _ => element == known_element(id),
        };
        if !allowed {
            return Err(format!("{what} has element type {}", element.name()));
        }
        if elements.checked_mul(element.bytes()) != Some(byte_len) || !byte_len.is_multiple_of(4) {
            return Err(format!(
                "{what} has {elements} {} elements in {byte_len} bytes",
                element.name()
            ));
        }
        let slot = &mut entries[id as usize];
        if slot.is_some() {
            return Err(format!("section {name} appears twice"));
        }
        // In bounds of the file, so they fit in usize.
        *slot = Some(Entry {
            element,
            byte_offset: byte_offset as usize,
            byte_len: byte_len as usize,
            count: elements,
        });
    }
    Ok(entries)
}

/// The element type of a known section other than the radiance.
fn known_element(id: u32) -> ElementType {
    match id {
        section::PARAMS => ElementType::U32,
        _ => sampling_element(id),
    }
}

/// The error for a sampling section the parameters call for and the file lacks.
fn missing(id: u32, params: &[u32; PARAMS_WORDS]) -> String {
    format!(
        "no {} section (id {id}), which the parameters ({}) call for",
        section::name(id).unwrap_or("?"),
        describe(params)
    )
}

/// `sampler S, density D` as the parameters name them.
fn describe(p: &[u32; PARAMS_WORDS]) -> String {
    let sampler = match p[param::SAMPLER] {
        value::SAMPLER_INVERSION => "inversion",
        _ => "alias",
    };
    let density = match p[param::DENSITY] {
        value::DENSITY_PIECEWISE_CONSTANT => "piecewise-constant",
        _ => "piecewise-bilinear",
    };
    format!("sampler {sampler}, density {density}")
}

/// Checks the parameter block's codes and sizes, and returns the sampling
/// sections they call for with their places in the tables buffer (in id order,
/// each padded to 16 bytes); the parameters' offsets and `tables_words` must be
/// exactly those.
fn expected_sampling(p: &[u32; PARAMS_WORDS]) -> std::result::Result<Vec<Placed>, String> {
    if p[param::VERSION] != VERSION {
        return Err(format!(
            "the parameter block says layout version {}, the header {VERSION}",
            p[param::VERSION]
        ));
    }
    for (word, name) in [
        (param::SAMPLER, "sampler"),
        (param::DENSITY, "density"),
        (param::MAPPING, "mapping"),
        (param::RADIANCE_FORMAT, "radiance_format"),
        (param::ROTATED, "rotated"),
        (param::BLACK, "black"),
    ] {
        if p[word] > 1 {
            return Err(format!(
                "parameter {name} (word {word}) is {}, not 0 or 1",
                p[word]
            ));
        }
    }
    if p[param::LOOKUP] > value::LOOKUP_NODE {
        return Err(format!(
            "parameter lookup (word {}) is {}, not 0, 1 or 2",
            param::LOOKUP,
            p[param::LOOKUP]
        ));
    }
    let bilinear = p[param::DENSITY] == value::DENSITY_PIECEWISE_BILINEAR;
    let alias = p[param::SAMPLER] == value::SAMPLER_ALIAS;
    let v_nodes = p[param::BILINEAR_V_NODES];
    let node_rows_allowed = bilinear
        && p[param::LOOKUP] == value::LOOKUP_NODE
        && p[param::MAPPING] == value::MAPPING_EQUIRECTANGULAR
        && p[param::IMAGE_HEIGHT] >= 2;
    if !(v_nodes == value::V_NODES_TEXEL_CENTRES
        || (v_nodes == value::V_NODES_NODE_ROWS && node_rows_allowed))
    {
        return Err(format!(
            "parameter bilinear_v_nodes (word {}) is {v_nodes}: 0, or 1 (node rows) only \
             for the piecewise-bilinear density with the node lookup on an equirectangular \
             map of at least 2 rows",
            param::BILINEAR_V_NODES
        ));
    }
    if bilinear && alias {
        return Err(
            "the parameters name the alias sampler with the piecewise-bilinear \
                    density, which is sampled by inversion only"
                .into(),
        );
    }
    let size = |word: usize, name: &str| -> std::result::Result<u64, String> {
        match p[word] {
            0 => Err(format!("parameter {name} (word {word}) is 0")),
            n => Ok(n as u64),
        }
    };
    let (iw, ih) = (
        size(param::IMAGE_WIDTH, "image_width")?,
        size(param::IMAGE_HEIGHT, "image_height")?,
    );
    let (tw, th) = (
        size(param::TABLE_WIDTH, "table_width")?,
        size(param::TABLE_HEIGHT, "table_height")?,
    );
    if bilinear && (tw != iw + 1 || th != ih + 1) {
        return Err(format!(
            "the piecewise-bilinear density's table is {tw}x{th} patches, not the \
             {}x{} of a {iw}x{ih} image",
            iw + 1,
            ih + 1
        ));
    }
    // Sizes come from the file: saturating products (which then match no
    // section) rather than overflow.
    let mul = |a: u64, b: u64| a.saturating_mul(b);
    let mut wanted: Vec<(u32, u64)> = Vec::new();
    if alias {
        let bits = p[param::ALIAS_OFFSET_BITS];
        if !(1..=24).contains(&bits) {
            return Err(format!(
                "parameter alias_offset_bits (word {}) is {bits}, not in 1..=24",
                param::ALIAS_OFFSET_BITS
            ));
        }
        wanted.push((section::ALIAS_SLOTS, mul(2, mul(tw, th))));
        wanted.push((section::ALIAS_FUNC, mul(tw, th)));
    } else {
        let shift = p[param::MARGINAL_GUIDE_SHIFT];
        if !(1..=32).contains(&shift) {
            return Err(format!(
                "parameter marginal_guide_shift (word {}) is {shift}, not in 1..=32",
                param::MARGINAL_GUIDE_SHIFT
            ));
        }
        let bits = p[param::CONDITIONAL_GUIDE_BITS];
        if bits > 31 {
            return Err(format!(
                "parameter conditional_guide_bits (word {}) is {bits}, not in 0..=31",
                param::CONDITIONAL_GUIDE_BITS
            ));
        }
        wanted.push((section::MARGINAL_CDF, th + 1));
        wanted.push((section::MARGINAL_GUIDE, 1u64 << (32 - shift)));
        wanted.push((section::CONDITIONAL_CDF, mul(th, tw + 1)));
        wanted.push((section::CONDITIONAL_GUIDE, mul(th, 1 << bits)));
        if bilinear {
            wanted.push((section::BILINEAR_VALUES, mul(ih + 2, iw + 2)));
        }
    }
    let mut placed = Vec::with_capacity(wanted.len());
    let mut offset = 0u64;
    for (id, words) in wanted {
        // Offsets and lengths are 32-bit words: anything larger cannot be what the
        // parameters say.
        let (Ok(word_offset), Ok(n)) = (usize::try_from(offset), usize::try_from(words)) else {
            return Err("the sections the parameters call for do not fit in memory".into());
        };
        if offset > u32::MAX as u64 {
            return Err("the sampling sections would need more than 2³² words".into());
        }
        placed.push(Placed {
            id,
            word_offset,
            words: n,
        });
        offset = offset.saturating_add(mul(words.div_ceil(ALIGN_WORDS as u64), ALIGN_WORDS as u64));
    }
    for id in section::SAMPLING {
        let word = param::offset_of(id).unwrap_or(param::RESERVED);
        let want = placed
            .iter()
            .find(|q| q.id == id)
            .map_or(0, |q| q.word_offset);
        if p[word] as usize != want {
            return Err(format!(
                "parameter {} (word {word}) is {}, but the sections the parameters call for \
                 put it at word {want} of the tables buffer",
                section::name(id).unwrap_or("?"),
                p[word]
            ));
        }
    }
    if p[param::TABLES_WORDS] as u64 != offset {
        return Err(format!(
            "parameter tables_words (word {}) is {}, but the sections the parameters call \
             for take {offset} words",
            param::TABLES_WORDS,
            p[param::TABLES_WORDS]
        ));
    }
    Ok(placed)
}

/// The checks a shader's memory safety rests on: every CDF runs from 0 to
/// `CDF_ONE` without decreasing (so the forward scan from a guide entry stops
/// inside the row), every guide entry names a cell of its CDF, every alias names
/// a cell and every threshold is in `[0, 1]`.
fn check_contents(t: &GpuTables) -> std::result::Result<(), String> {
    let p = &t.params;
    let (tw, th) = (
        p[param::TABLE_WIDTH] as usize,
        p[param::TABLE_HEIGHT] as usize,
    );
    let words = |id: u32| t.section_words(id).unwrap_or(&[]);
    if p[param::SAMPLER] == value::SAMPLER_ALIAS {
        let n = (tw * th) as u64;
        for (k, slot) in words(section::ALIAS_SLOTS).chunks_exact(2).enumerate() {
            let threshold = f32::from_bits(slot[0]);
            if !(0.0..=1.0).contains(&threshold) || slot[1] as u64 >= n {
                return Err(format!(
                    "alias slot {k} has threshold {threshold} and alias {}: the threshold \
                     must be in [0, 1] and the alias below {n}",
                    slot[1]
                ));
            }
        }
        return Ok(());
    }
    check_cdfs(
        "marginal_cdf",
        words(section::MARGINAL_CDF),
        th,
        words(section::MARGINAL_GUIDE),
    )?;
    check_cdfs(
        "conditional_cdf",
        words(section::CONDITIONAL_CDF),
        tw,
        words(section::CONDITIONAL_GUIDE),
    )
}

/// Checks rows of `n + 1` CDF values (`cdf.len() / (n + 1)` of them) and their
/// guide tables (`guide.len()` split evenly among the rows).
fn check_cdfs(name: &str, cdf: &[u32], n: usize, guide: &[u32]) -> std::result::Result<(), String> {
    let rows = cdf.len() / (n + 1);
    for (r, row) in cdf.chunks_exact(n + 1).enumerate() {
        let ends = (row.first(), row.last());
        if ends != (Some(&0), Some(&CDF_ONE)) || row.windows(2).any(|w| w[0] > w[1]) {
            return Err(format!(
                "{name} row {r} does not rise from 0 to {CDF_ONE} without decreasing"
            ));
        }
    }
    if let Some(k) = guide.iter().position(|&g| g as usize >= n) {
        let per_row = guide.len() / rows.max(1);
        return Err(format!(
            "the guide of {name} row {} names cell {} of {n}",
            k / per_row.max(1),
            guide[k]
        ));
    }
    Ok(())
}
