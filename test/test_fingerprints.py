"""Reading and validating fingerprint CSVs (no ROS, no torch)."""

import hashlib
import zipfile

from conftest import dataset_file, mac, synthetic_csv
import numpy as np
import pytest
from wifi_place_recognition.data.files import DataError, download_uci
from wifi_place_recognition.data.fingerprints import (
    parse_fingerprints, read_fingerprints)

HEADER = 'WAP001,WAP002,FLOOR,BUILDINGID,PHONEID'


def parse(text):
    return parse_fingerprints(text, ('f.csv', text.encode()))


def test_generic_csv_with_mac_columns(tmp_path):
    fp = read_fingerprints(synthetic_csv(tmp_path / 'a.csv', n_aps=7))
    assert fp.ap_ids == tuple(mac(i) for i in range(7))
    assert fp.rssi.shape == (240, 7)
    assert set(zip(fp.building, fp.floor)) == {(0, 0), (0, 1), (1, 0), (1, 1)}
    assert np.isnan(fp.rssi).any()          # 100 -> not detected
    assert 'PHONEID' in fp.meta


def test_values_above_zero_are_clipped_and_counted():
    fp = parse(f'{HEADER}\n-50,5,0,0,1\n-50,100,1,0,1\n-50,-70,1,0,1\n')
    assert fp.rssi[0, 1] == 0.0
    assert fp.clipped == 1
    assert np.isnan(fp.rssi[1, 1])
    assert fp.notes == []


def test_rows_without_any_ap_are_kept_and_flagged():
    fp = parse(f'{HEADER}\n100,100,0,0,1\n-50,-60,1,0,1\n')
    assert fp.empty_rows.tolist() == [True, False]


@pytest.mark.parametrize('text, message', [
    ('', 'empty file'),
    (f'{HEADER}\n', 'no data rows'),
    ('WAP001,WAP002,FLOOR\n-50,-60,1\n', 'missing label column(s) BUILDINGID'),
    ('WAP001;WAP002;FLOOR;BUILDINGID\n-50;-60;1;0\n',
     'single column: is the file comma-separated?'),
    (f'{HEADER}\n-50,-60,0,0,1\n-50,0,1\n', 'row 3 has 3 fields'),
    (f'{HEADER}\n-50,-60,0,0,1\n-50,abc,0,0,1\n',
     "row 3, column WAP002: value 'abc'"),
    (f'{HEADER}\n-50,-60,0,0,1\n-50,nan,0,0,1\n',
     'row 3, column WAP002: value nan'),
    (f'{HEADER}\n-50,-60,0,0,1\n-50,-400,0,0,1\n',
     'row 3, column WAP002: RSSI -400 dBm is outside'),
    (f'{HEADER}\n-50,-60,0,0,1\n-50,60,0,0,1\n',
     'row 3, column WAP002: RSSI 60'),
    (f'{HEADER}\n-50,-60,0,0,1\n\n-50,-60,x,0,1\n',
     "row 4, column FLOOR: value 'x' is not a number"),
    (f'{HEADER}\n-50,-60,0,0,1\n\n-50,-60,0,0,1\n-50,-60,0,nan,1\n',
     'row 5, column BUILDINGID: value nan is not a finite'),
    (f'{HEADER}\n-50,-60,1.5,0,1\n', 'row 2, column FLOOR: value 1.5'),
    (f'{HEADER}\n-50,-60,0,-1,1\n', 'row 2, column BUILDINGID: value -1'),
    ('WAP001,WAP001,FLOOR,BUILDINGID\n-50,-60,1,0\n',
     "column 'WAP001' appears twice"),
    ('FLOOR,BUILDINGID\n1,0\n', 'no AP columns'),
])
def test_bad_csv_names_file_row_and_column(text, message):
    with pytest.raises(DataError) as err:
        parse(text)
    assert str(err.value).startswith('f.csv: ')
    assert message in str(err.value)


def test_unreadable_and_binary_files(tmp_path):
    with pytest.raises(DataError, match='cannot read'):
        read_fingerprints(tmp_path / 'missing.csv')
    (tmp_path / 'bin.csv').write_bytes(b'\xff\xfe\x00garbage')
    with pytest.raises(DataError, match='not UTF-8'):
        read_fingerprints(tmp_path / 'bin.csv')


def _uci_zip(path, training_text):
    with zipfile.ZipFile(path, 'w') as zf:
        zf.writestr('UJIndoorLoc/trainingData.csv', training_text)
        zf.writestr('UJIndoorLoc/validationData.csv', training_text)
    return path


def test_reads_members_of_the_uci_zip(tmp_path):
    text = synthetic_csv(tmp_path / 'x.csv').read_text()
    archive = _uci_zip(tmp_path / 'uci.zip', text)
    train = read_fingerprints(archive, role='train')
    assert train.source.endswith('#UJIndoorLoc/trainingData.csv')
    assert len(read_fingerprints(archive, role='test')) == len(train)
    with pytest.raises(DataError, match="no member 'nope.csv'"):
        read_fingerprints(f'{archive}#nope.csv')


def test_a_damaged_member_of_a_zip_is_one_clear_error(tmp_path):
    archive = tmp_path / 'uci.zip'
    with zipfile.ZipFile(archive, 'w', zipfile.ZIP_DEFLATED) as zf:
        zf.writestr('trainingData.csv',
                    synthetic_csv(tmp_path / 'x.csv').read_text())
    data = bytearray(archive.read_bytes())
    with zipfile.ZipFile(archive) as zf:
        info = zf.infolist()[0]
    local = info.header_offset    # 30 fixed bytes, then name and extra
    data[local + 30 + int.from_bytes(data[local + 26:local + 28], 'little')
         + int.from_bytes(data[local + 28:local + 30], 'little')] = 0xff
    archive.write_bytes(bytes(data))     # its first deflate block: reserved
    with pytest.raises(DataError, match='cannot read: Error -3 while '
                                        'decompressing data'):
        read_fingerprints(archive, role='train')


def test_download_verifies_the_training_member(tmp_path):
    text = synthetic_csv(tmp_path / 'x.csv').read_text()
    archive = _uci_zip(tmp_path / 'uci.zip', text)
    url = archive.as_uri()
    good = hashlib.sha256(text.encode()).hexdigest()
    with pytest.raises(DataError, match='SHA-256'):
        download_uci(tmp_path / 'bad-cache', url, sha256='0' * 64)
    assert list((tmp_path / 'bad-cache').iterdir()) == []  # nothing left
    got = download_uci(tmp_path / 'cache', url, sha256=good)
    assert got.read_bytes() == archive.read_bytes()
    with pytest.raises(DataError, match='download failed'):
        download_uci(tmp_path / 'c2', (tmp_path / 'none.zip').as_uri())


def _digest(*arrays):
    return hashlib.sha256(b''.join(a.tobytes() for a in arrays)).hexdigest()


def test_real_training_file():
    """Read UJIIndoorLoc as before: the shipped model depends on it."""
    fp = read_fingerprints(dataset_file('trainingData.csv'))
    assert fp.rssi.shape == (19937, 520) and fp.rssi.dtype == np.float32
    assert fp.sha256.startswith('45ca0128')
    assert int(fp.empty_rows.sum()) == 76
    assert len(set(zip(fp.building, fp.floor))) == 13
    # digests of the arrays the reader before multi-format reading returned
    assert _digest(np.nan_to_num(fp.rssi, nan=100)).startswith(
        'da81c92cca1cbc3b')
    assert _digest(fp.building, fp.floor).startswith('397dada8b8cf45cf')
    assert fp.notes == [] and fp.walk is None
    assert fp.position_columns == ('LONGITUDE', 'LATITUDE')
    assert fp.position.dtype == np.float64
    assert fp.position[0].tolist() == [-7541.2642999999225, 4864920.7782000005]
    assert fp.meta['PHONEID'].dtype == np.int64
    assert fp.meta['TIMESTAMP'].dtype == np.float64
    assert fp.meta['TIMESTAMP'][0] == 1371713733
    assert 'LONGITUDE' not in fp.meta
    assert '18.0 detected per scan on average' in fp.summary()
