//! The chart font, shared by the programs that draw charts (the benchmark, `density_figures`).

use plotters::style::FontStyle;

/// Registers DejaVu Sans as "sans-serif": plotters' ab_glyph backend needs a font registered
/// by name; DejaVu ships with Debian.
pub fn register() {
    for path in [
        "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
        "/usr/share/fonts/TTF/DejaVuSans.ttf",
    ] {
        if let Ok(bytes) = std::fs::read(path) {
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, bytes);
            return;
        }
    }
    eprintln!("warning: no DejaVuSans.ttf found; chart text will be missing");
}
