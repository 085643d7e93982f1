//! The GLB v2 container (glTF 2.0 §4.4): a 12-byte header, the JSON chunk and the BIN chunk.
//! Every `.glb` lightbake writes (bake output, test scenes) comes from [`container`].

/// A GLB file of `json` (padded with spaces) and `bin` (padded with zeros) to 4-byte chunk
/// lengths. An empty `bin` writes no BIN chunk, as the spec allows.
pub(crate) fn container(mut json: Vec<u8>, mut bin: Vec<u8>) -> Vec<u8> {
    json.resize(json.len().next_multiple_of(4), b' ');
    bin.resize(bin.len().next_multiple_of(4), 0);
    let bin_chunk = if bin.is_empty() { 0 } else { 8 + bin.len() };
    let total = 12 + 8 + json.len() + bin_chunk;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_are_padded_and_the_header_counts_every_byte() {
        let glb = container(b"{}".to_vec(), vec![1, 2, 3, 4, 5]);
        assert_eq!(glb.len(), 12 + 8 + 4 + 8 + 8);
        assert_eq!(&glb[..4], b"glTF");
        assert_eq!(u32::from_le_bytes(glb[8..12].try_into().unwrap()), 40);
        assert_eq!(&glb[12..24], b"\x04\0\0\0JSON{}  ");
        assert_eq!(&glb[24..32], b"\x08\0\0\0BIN\0");
        assert_eq!(&glb[32..], &[1, 2, 3, 4, 5, 0, 0, 0]);
        let parsed = gltf::binary::Glb::from_slice(&glb).unwrap();
        assert_eq!(parsed.json.as_ref(), b"{}  ");
        // No geometry: no BIN chunk.
        assert_eq!(container(b"{}".to_vec(), Vec::new()).len(), 24);
    }
}
