// PNG read / write with libpng's simplified API (libpng >= 1.6).
#include "ltmapper/io/io.hpp"
#include "ltmapper/viz/viz.hpp"

#include <png.h>

#include <cstring>

namespace ltm::viz {

Image::Image(int w, int h, Rgb fill) : width(w), height(h), rgb(std::size_t(w) * h * 3) {
  for (std::size_t k = 0; k < rgb.size(); k += 3) {
    rgb[k] = fill.r;
    rgb[k + 1] = fill.g;
    rgb[k + 2] = fill.b;
  }
}

void WritePng(const std::string& path, const Image& image) {
  if (image.width <= 0 || image.height <= 0 ||
      image.rgb.size() != std::size_t(image.width) * image.height * 3)
    throw Error(path, 0, "WritePng: bad image " + std::to_string(image.width) + " x " +
                             std::to_string(image.height));
  io::WritePathAtomic(path, [&](const std::string& tmp) {
    png_image png;
    std::memset(&png, 0, sizeof(png));
    png.version = PNG_IMAGE_VERSION;
    png.width = png_uint_32(image.width);
    png.height = png_uint_32(image.height);
    png.format = PNG_FORMAT_RGB;
    if (!png_image_write_to_file(&png, tmp.c_str(), 0, image.rgb.data(), 0, nullptr)) {
      const std::string msg = png.message;
      png_image_free(&png);
      throw Error(path, 0, "cannot write PNG: " + msg);
    }
  });
}

Image ReadPng(const std::string& path) {
  png_image png;
  std::memset(&png, 0, sizeof(png));
  png.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&png, path.c_str()))
    throw Error(path, 0, std::string("cannot read PNG: ") + png.message);
  png.format = PNG_FORMAT_RGB;
  Image img;
  img.width = int(png.width);
  img.height = int(png.height);
  img.rgb.resize(PNG_IMAGE_SIZE(png));
  if (!png_image_finish_read(&png, nullptr, img.rgb.data(), 0, nullptr)) {
    const std::string msg = png.message;
    png_image_free(&png);
    throw Error(path, 0, "cannot decode PNG: " + msg);
  }
  return img;
}

}  // namespace ltm::viz
