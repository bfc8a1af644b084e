//! What every figure arlux draws shares: the font shipped in `assets/`
//! (no system font needed), registered once with plotters.

/// Registers the shipped font as plotters' "sans-serif" (once per process).
pub(crate) fn register_font() {
    static FONT: &[u8] = include_bytes!("fonts/DejaVuSans.ttf");
    static REGISTERED: std::sync::Once = std::sync::Once::new();
    REGISTERED.call_once(|| {
        let _ =
            plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, FONT);
    });
}
