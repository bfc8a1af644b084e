//! Writes an EXR as an sRGB PNG (for documentation pictures).
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let img = arlux::image_io::read_image(std::path::Path::new(&a[1])).unwrap();
    arlux::image_io::write_png(std::path::Path::new(&a[2]), &img, 0.0).unwrap();
}
