// Writes DICOM slices with GDCM for the tests (test_io, test_cli).
#pragma once

#include <gdcmAttribute.h>
#include <gdcmImage.h>
#include <gdcmImageWriter.h>
#include <gdcmReader.h>
#include <gdcmTrace.h>
#include <gdcmWriter.h>
#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <type_traits>
#include <vector>

#include "dicom_enhanced.hpp"

namespace simdvol::testing {

/// One slice of a classic (single-frame) DICOM series, as GDCM's writer
/// writes it: CT Image Storage, `nx` x `ny` pixels of T, its position
/// (Image Position (Patient)), the row and column directions, the pixel
/// spacing (x, y), Rescale Slope and Intercept, and a Series Instance UID.
struct DicomSlice {
  std::array<double, 3> position{0, 0, 0};
  std::array<double, 6> cosines{1, 0, 0, 0, 1, 0};
  std::array<double, 2> spacing{0.5, 0.7};
  double slope = 1.0, intercept = 0.0;
  std::string series = "1.2.826.0.1.3680043.10.1.1";
  int samples = 1;
  bool orientation = true;   ///< false: Image Orientation (Patient) taken out
  bool has_position = true;  ///< false: Image Position (Patient) taken out
  int instance = 0;          ///< Instance Number, where not 0
  int temporal = 0;          ///< Temporal Position Identifier, where not 0
  std::string image_type;    ///< Image Type, where not empty
  std::string description;   ///< Series Description, where not empty
};

template <typename T>
void write_dicom_slice(const std::filesystem::path& p, int nx, int ny, const std::vector<T>& pixels,
                       const DicomSlice& s) {
  gdcm::Trace::WarningOff();  // (what the writer fills in itself)
  gdcm::ImageWriter w;
  gdcm::Image& im = w.GetImage();
  im.SetNumberOfDimensions(2);  // (3 would make it an enhanced multi-frame file)
  im.SetDimension(0, static_cast<unsigned int>(nx));
  im.SetDimension(1, static_cast<unsigned int>(ny));
  gdcm::PixelFormat pf = std::is_same_v<T, uint8_t>    ? gdcm::PixelFormat::UINT8
                         : std::is_same_v<T, uint16_t> ? gdcm::PixelFormat::UINT16
                                                       : gdcm::PixelFormat::INT16;
  pf.SetSamplesPerPixel(static_cast<uint16_t>(s.samples));
  im.SetPixelFormat(pf);
  im.SetPhotometricInterpretation(s.samples == 3 ? gdcm::PhotometricInterpretation::RGB
                                                 : gdcm::PhotometricInterpretation::MONOCHROME2);
  im.SetSpacing(0, s.spacing[0]);
  im.SetSpacing(1, s.spacing[1]);
  for (unsigned int a = 0; a < 3; ++a) im.SetOrigin(a, s.position[a]);
  im.SetDirectionCosines(s.cosines.data());
  im.SetSlope(s.slope);
  im.SetIntercept(s.intercept);
  gdcm::DataElement pd(gdcm::Tag(0x7fe0, 0x0010));
  pd.SetByteValue(reinterpret_cast<const char*>(pixels.data()),
                  static_cast<uint32_t>(pixels.size() * sizeof(T)));
  im.SetDataElement(pd);
  gdcm::DataSet& ds = w.GetFile().GetDataSet();
  gdcm::Attribute<0x0008, 0x0016> sop;
  sop.SetValue("1.2.840.10008.5.1.4.1.1.2");  // CT Image Storage
  ds.Replace(sop.GetAsDataElement());
  gdcm::Attribute<0x0020, 0x000e> uid;
  uid.SetValue(s.series);
  ds.Replace(uid.GetAsDataElement());
  if (s.instance != 0) {
    gdcm::Attribute<0x0020, 0x0013> number;
    number.SetValue(s.instance);
    ds.Replace(number.GetAsDataElement());
  }
  gdcm::Attribute<0x0008, 0x0060> modality;
  modality.SetValue("CT");
  ds.Replace(modality.GetAsDataElement());
  if (!s.description.empty()) {
    gdcm::Attribute<0x0008, 0x103e> description;
    description.SetValue(s.description);
    ds.Replace(description.GetAsDataElement());
  }
  if (!s.image_type.empty()) {
    gdcm::DataElement type(gdcm::Tag(0x0008, 0x0008));
    type.SetVR(gdcm::VR::CS);
    type.SetByteValue(s.image_type.data(), static_cast<uint32_t>(s.image_type.size()));
    ds.Replace(type);
  }
  if (s.temporal != 0) {
    gdcm::Attribute<0x0020, 0x0100> when;
    when.SetValue(s.temporal);
    ds.Replace(when.GetAsDataElement());
  }
  w.SetFileName(p.c_str());
  ASSERT_TRUE(w.Write()) << p;
  if (!s.orientation || !s.has_position) {  // (GDCM's image writer always writes them)
    gdcm::Reader r;
    r.SetFileName(p.c_str());
    ASSERT_TRUE(r.Read()) << p;
    if (!s.orientation) r.GetFile().GetDataSet().Remove(gdcm::Tag(0x0020, 0x0037));
    if (!s.has_position) r.GetFile().GetDataSet().Remove(gdcm::Tag(0x0020, 0x0032));
    gdcm::Writer again;
    again.SetFile(r.GetFile());
    again.SetFileName(p.c_str());
    ASSERT_TRUE(again.Write()) << p;
  }
}

}  // namespace simdvol::testing
