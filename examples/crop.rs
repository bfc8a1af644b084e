use arlux::image_io::*;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let imgs: Vec<Image> = a[1..3].iter().map(|p| read_image(std::path::Path::new(p)).unwrap()).collect();
    let (x0, y0, w, h, s) = (280u32, 225u32, 80u32, 80u32, 4u32);
    let mut out = Image::new(3 * w * s, h * s);
    for (k, img) in imgs.iter().enumerate() {
        for y in 0..h * s { for x in 0..w * s { out.set(k as u32 * w * s + x, y, img.get(x0 + x / s, y0 + y / s)); } }
    }
    for y in 0..h * s { for x in 0..w * s { let d = imgs[0].get(x0 + x / s, y0 + y / s) - imgs[1].get(x0 + x / s, y0 + y / s); out.set(2 * w * s + x, y, glam::Vec3::new(d.x.max(0.0), d.x.abs()*0.0, (-d.x).max(0.0)) * 4.0); } }
    write_png(std::path::Path::new(&a[3]), &out, 0.0).unwrap();
}
