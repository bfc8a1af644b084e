//! [`BandComparison`]: a render's [`Comparison`] and [`Skill`] against its
//! reference, added up band by band as the render writes its bands, so
//! that neither the image nor the reference is held whole.

use std::collections::VecDeque;

use glam::Vec3;

use super::{
    CHANGE_RADIUS, Comparison, Skill, Sums, change_values, horizontal_sums, is_changed, row_sums,
    vertical_means, window_rows,
};
use crate::image_io::Image;

/// The figures of [`super::compare`] (no mask) and [`super::skill`] of a
/// result against a truth, from their rows handed over in order, equal to
/// those of the whole images bit for bit whatever the bands.
pub struct BandComparison<'a> {
    /// The photo the change is measured from, the compared window's size.
    photo: &'a Image,
    /// Rows received.
    received: usize,
    /// The first row of `rows`.
    first: usize,
    /// Per row from `first` on, while a change window may still read it:
    /// the result, the truth and the change values' horizontal sums.
    rows: VecDeque<Row>,
    /// The next row whose figures are added.
    next: usize,
    all: Sums,
    ours: Sums,
    photo_error: Sums,
}

struct Row {
    result: Vec<Vec3>,
    truth: Vec<Vec3>,
    sums: Vec<[f64; 2]>,
}

impl<'a> BandComparison<'a> {
    /// A comparison of images of `photo`'s size.
    pub fn new(photo: &'a Image) -> BandComparison<'a> {
        BandComparison {
            photo,
            received: 0,
            first: 0,
            rows: VecDeque::new(),
            next: 0,
            all: Sums::default(),
            ours: Sums::default(),
            photo_error: Sums::default(),
        }
    }

    fn width(&self) -> usize {
        self.photo.width as usize
    }

    fn height(&self) -> usize {
        self.photo.height as usize
    }

    /// The next rows of the result and of the truth (whole rows, as many
    /// of each).
    pub fn push(&mut self, result: &[Vec3], truth: &[Vec3]) {
        let w = self.width().max(1);
        assert_eq!(result.len(), truth.len(), "as many rows of each");
        assert_eq!(result.len() % w, 0, "whole rows");
        for (r, t) in result.chunks(w).zip(truth.chunks(w)) {
            let y = self.received;
            assert!(y < self.height(), "more rows than the photo has");
            let p = &self.photo.pixels[y * w..(y + 1) * w];
            let values: Vec<[f64; 2]> = t
                .iter()
                .zip(p)
                .map(|(t, p)| change_values(*t, *p))
                .collect();
            self.rows.push_back(Row {
                result: r.to_vec(),
                truth: t.to_vec(),
                sums: horizontal_sums(&values, CHANGE_RADIUS),
            });
            self.received += 1;
            while self.next < self.received
                && (self.next + CHANGE_RADIUS).min(self.height() - 1) < self.received
            {
                self.add_row();
            }
        }
    }

    /// Adds row `next`'s figures (its change window's rows all received).
    fn add_row(&mut self) {
        let (y, w) = (self.next, self.width());
        let rows: Vec<&[[f64; 2]]> = window_rows(y, CHANGE_RADIUS, self.height())
            .map(|row| self.rows[row - self.first].sums.as_slice())
            .collect();
        let mut means = vec![[0.0; 2]; w];
        vertical_means(&rows, &mut means);
        let changed: Vec<bool> = means.into_iter().map(is_changed).collect();
        let row = &self.rows[y - self.first];
        let photo = &self.photo.pixels[y * w..(y + 1) * w];
        self.all.add(&row_sums(&row.result, &row.truth, None));
        self.ours
            .add(&row_sums(&row.result, &row.truth, Some(&changed)));
        (self.photo_error).add(&row_sums(photo, &row.truth, Some(&changed)));
        self.next += 1;
        // The next row's window starts at next − radius.
        while self.first + CHANGE_RADIUS < self.next {
            self.rows.pop_front();
            self.first += 1;
        }
    }

    /// Rows still to hand over.
    pub fn rows_left(&self) -> usize {
        self.height() - self.received
    }

    /// The figures, once every row has been handed over.
    pub fn finish(self) -> (Comparison, Skill) {
        assert_eq!(self.rows_left(), 0, "every row handed over");
        (
            self.all.comparison(),
            Skill::of(self.ours.comparison(), self.photo_error.comparison()),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compare::{compare, skill};

    /// A photo, a truth that darkens a disc of it, and a result between.
    fn images(w: u32, h: u32) -> (Image, Image, Image) {
        let mut photo = Image::new(w, h);
        let (mut truth, mut result) = (photo.clone(), photo.clone());
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                let noise = ((i * 7919) % 101) as f32 / 101.0;
                let p = Vec3::new(0.3 + 0.2 * noise, 0.4, 0.5 - 0.1 * noise);
                let (dx, dy) = (x as f32 - w as f32 / 2.0, y as f32 - h as f32 / 2.0);
                let shade = if dx * dx + dy * dy < 0.1 * (w * w) as f32 {
                    0.6
                } else {
                    1.0
                };
                photo.pixels[i] = p;
                truth.pixels[i] = p * shade;
                result.pixels[i] = p * (0.5 + 0.5 * shade) + Vec3::splat(0.01 * noise);
            }
        }
        (photo, truth, result)
    }

    #[test]
    fn bands_of_any_height_give_the_whole_images_figures_bit_for_bit() {
        let (photo, truth, result) = images(37, 29);
        let whole = (
            compare(&result, &truth, None),
            skill(&result, &truth, &photo),
        );
        assert!(whole.1.changed_pixels > 100 && whole.1.skill.unwrap() > 0.3);
        for rows in [1usize, 2, 3, 5, 7, 29] {
            let mut bands = BandComparison::new(&photo);
            let w = photo.width as usize;
            for start in (0..29).step_by(rows) {
                let end = (start + rows).min(29);
                bands.push(
                    &result.pixels[start * w..end * w],
                    &truth.pixels[start * w..end * w],
                );
            }
            let (c, s) = bands.finish();
            assert_eq!(c.rmse.to_bits(), whole.0.rmse.to_bits(), "{rows} rows");
            assert_eq!(c.mean.to_bits(), whole.0.mean.to_bits());
            assert_eq!(c.psnr_srgb_db, whole.0.psnr_srgb_db);
            assert_eq!(s, whole.1, "{rows} rows");
        }
    }

    #[test]
    fn an_image_of_one_or_two_rows_is_compared_too() {
        for h in [1, 2] {
            let (photo, truth, result) = images(9, h);
            let mut bands = BandComparison::new(&photo);
            bands.push(&result.pixels, &truth.pixels);
            let (c, s) = bands.finish();
            assert_eq!(c, compare(&result, &truth, None));
            assert_eq!(s, skill(&result, &truth, &photo));
        }
    }
}
